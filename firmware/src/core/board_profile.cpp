#include "board_profile.h"

#include "flash_table.h"

namespace sphere {

// [profile][chip][body axis]. Sources: SparkFun SEN-10724 (9DoF Sensor Stick) — the sign table of the
// Razor AHRS firmware for hardware version 10724 (accelerometer and gyroscope share one frame there,
// the HMC5883L is turned 90° about z); GY-85 — UNVERIFIED: no datasheet or schematic gives its chips'
// orientation and no GY-85 has confirmed this row; the virtual board copies it (protocol/spec.md §4.2.1 tells
// how it came about). `sphere calibrate`'s axis check says which profile a board matches.
static const uint8_t MAPS[BOARD_PROFILE_COUNT][3][3] SPHERE_TABLE = {
    {{0, 1, 2}, {0, 1, 2}, {0, 1, 2}},                                 // aligned
    {{0, 1, 2}, {0, 1, 2}, {1, 0 | AXIS_NEG, 2}},                      // sen10724: mag (+y, −x, +z)
    {{0, 1, 2}, {0 | AXIS_NEG, 1 | AXIS_NEG, 2}, {1 | AXIS_NEG, 0, 2}},  // gy85: gyro (−x, −y, +z), mag (−y, +x, +z)
};

void axisMap(uint8_t profile, uint8_t chip, uint8_t out[3]) {
    for (uint8_t i = 0; i < 3; ++i) out[i] = SPHERE_READ_U8(&MAPS[profile][chip][i]);
}

void mapAxes(uint8_t profile, uint8_t chip, int16_t v[3]) {
    uint8_t m[3];
    axisMap(profile, chip, m);
    int16_t in[3] = {v[0], v[1], v[2]};
    for (uint8_t i = 0; i < 3; ++i) {
        int16_t x = in[m[i] & 3];
        // negating −32768 saturates; the magnetometer's overflow mark −4096 keeps its meaning (the gyroscope's
        // and the accelerometer's −4096 is a reading like any other: kept, it turned 285 °/s into −285 °/s)
        if ((m[i] & AXIS_NEG) && !(chip == CHIP_MAG && x == -4096)) x = x == -32768 ? 32767 : (int16_t)-x;
        v[i] = x;
    }
}

}  // namespace sphere
