#include "calibration.h"

#include "bytes.h"
#include "crc16.h"
#include "fixed_math.h"

namespace sphere {

void Calibration::setDefaults() {
    for (uint8_t i = 0; i < 3; ++i) {
        gyro_bias[i] = 0;
        accel_offset[i] = 0;
        accel_scale[i] = Q14_ONE;
        mag_offset[i] = 0;
    }
    for (uint8_t i = 0; i < 9; ++i) mag_soft_iron[i] = (i % 4 == 0) ? Q14_ONE : 0;
}

bool Calibration::gyroIsDefault() const { return !gyro_bias[0] && !gyro_bias[1] && !gyro_bias[2]; }

bool Calibration::accelIsDefault() const {
    for (uint8_t i = 0; i < 3; ++i)
        if (accel_offset[i] != 0 || accel_scale[i] != Q14_ONE) return false;
    return true;
}

bool Calibration::magIsDefault() const {
    for (uint8_t i = 0; i < 3; ++i)
        if (mag_offset[i] != 0) return false;
    for (uint8_t i = 0; i < 9; ++i)
        if (mag_soft_iron[i] != ((i % 4 == 0) ? Q14_ONE : 0)) return false;
    return true;
}

static bool within(const int16_t* v, uint8_t n, int16_t lo, int16_t hi) {
    for (uint8_t i = 0; i < n; ++i)
        if (v[i] < lo || v[i] > hi) return false;
    return true;
}

bool Calibration::valid() const {
    if (!within(gyro_bias, 3, -1000, 1000) || !within(accel_offset, 3, -512, 512) ||
        !within(accel_scale, 3, Q14_ONE / 2, 32767) || !within(mag_offset, 3, -2048, 2048))
        return false;
    // determinant from Q7 entries (|entry| ≤ 256): each triple product < 2^24, the sum < 2^27
    int32_t m[9];
    for (uint8_t i = 0; i < 9; ++i) m[i] = mag_soft_iron[i] >> 7;
    int32_t det = m[0] * (m[4] * m[8] - m[5] * m[7]) - m[1] * (m[3] * m[8] - m[5] * m[6]) +
                  m[2] * (m[3] * m[7] - m[4] * m[6]);  // Q21
    return det >= (1l << 17) || det <= -(1l << 17);  // |det| ≥ 1/16
}

void writeCalibrationBlock(const Calibration& c, uint8_t* out) {
    const uint8_t* p = (const uint8_t*)&c;
    for (uint8_t i = 0; i < CALIBRATION_BLOCK_LEN; ++i) out[i] = p[i];
}

void readCalibrationBlock(const uint8_t* in, Calibration& c) {
    uint8_t* p = (uint8_t*)&c;
    for (uint8_t i = 0; i < CALIBRATION_BLOCK_LEN; ++i) p[i] = in[i];
}

void writeCalibrationImage(const Calibration& c, uint8_t* image) {
    image[0] = CALIBRATION_EEPROM_VERSION;
    writeCalibrationBlock(c, image + 1);
    putU16(image + 1 + CALIBRATION_BLOCK_LEN, crc16(image, 1 + CALIBRATION_BLOCK_LEN));
}

bool readCalibrationImage(const uint8_t* image, Calibration& c) {
    if (image[0] != CALIBRATION_EEPROM_VERSION) return false;
    if (crc16(image, 1 + CALIBRATION_BLOCK_LEN) != getU16(image + 1 + CALIBRATION_BLOCK_LEN)) return false;
    Calibration read;
    readCalibrationBlock(image + 1, read);
    if (!read.valid()) return false;
    c = read;
    return true;
}

int16_t saturate16(int32_t v) {
    if (v > 32767) return 32767;
    if (v < -32768) return -32768;
    return (int16_t)v;
}

void applyGyro(const Calibration& c, const int16_t raw[3], int16_t out[3]) {
    for (uint8_t i = 0; i < 3; ++i) out[i] = saturate16((int32_t)raw[i] - c.gyro_bias[i]);
}

// raw − offset, limited to ±8191 so that the Q14 products below cannot overflow (the chips' own
// ranges are ±4096 and ±2048)
static int16_t centred(int16_t raw, int16_t offset) {
    int32_t d = (int32_t)raw - offset;
    return (int16_t)(d > 8191 ? 8191 : d < -8191 ? -8191 : d);
}

void applyAccel(const Calibration& c, const int16_t raw[3], int16_t out[3]) {
    for (uint8_t i = 0; i < 3; ++i)
        out[i] = saturate16((mac2(centred(raw[i], c.accel_offset[i]), c.accel_scale[i], 0, 0) + 8192) >> 14);
}

void applyMag(const Calibration& c, const int16_t raw[3], int16_t out[3]) {
    int16_t d[3];
    for (uint8_t i = 0; i < 3; ++i) d[i] = centred(raw[i], c.mag_offset[i]);
    const int16_t* m = c.mag_soft_iron;
    for (uint8_t r = 0; r < 3; ++r, m += 3)
        out[r] = saturate16((mac3(d[0], m[0], d[1], m[1], d[2], m[2]) + 8192) >> 14);
}

}  // namespace sphere
