#include "calibration.h"

#include "bytes.h"
#include "crc16.h"

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

static const int16_t* field(const Calibration& c, uint8_t i) {
    // the 21 values in block order
    if (i < 3) return &c.gyro_bias[i];
    if (i < 6) return &c.accel_offset[i - 3];
    if (i < 9) return &c.accel_scale[i - 6];
    if (i < 12) return &c.mag_offset[i - 9];
    return &c.mag_soft_iron[i - 12];
}

void writeCalibrationBlock(const Calibration& c, uint8_t* out) {
    for (uint8_t i = 0; i < 21; ++i) putI16(out + 2 * i, *field(c, i));
}

void readCalibrationBlock(const uint8_t* in, Calibration& c) {
    for (uint8_t i = 0; i < 21; ++i) *const_cast<int16_t*>(field(c, i)) = getI16(in + 2 * i);
}

void writeCalibrationImage(const Calibration& c, uint8_t* image) {
    image[0] = CALIBRATION_EEPROM_VERSION;
    writeCalibrationBlock(c, image + 1);
    putU16(image + 1 + CALIBRATION_BLOCK_LEN, crc16(image, 1 + CALIBRATION_BLOCK_LEN));
}

bool readCalibrationImage(const uint8_t* image, Calibration& c) {
    if (image[0] != CALIBRATION_EEPROM_VERSION) return false;
    if (crc16(image, 1 + CALIBRATION_BLOCK_LEN) != getU16(image + 1 + CALIBRATION_BLOCK_LEN)) return false;
    readCalibrationBlock(image + 1, c);
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

void applyAccel(const Calibration& c, const int16_t raw[3], int16_t out[3]) {
    for (uint8_t i = 0; i < 3; ++i) {
        int32_t d = (int32_t)raw[i] - c.accel_offset[i];
        out[i] = saturate16((d * c.accel_scale[i] + 8192) >> 14);
    }
}

void applyMag(const Calibration& c, const int16_t raw[3], int16_t out[3]) {
    int32_t d[3];
    for (uint8_t i = 0; i < 3; ++i) d[i] = (int32_t)raw[i] - c.mag_offset[i];
    for (uint8_t r = 0; r < 3; ++r) {
        int32_t s = 0;
        for (uint8_t k = 0; k < 3; ++k) s += d[k] * c.mag_soft_iron[3 * r + k];
        out[r] = saturate16((s + 8192) >> 14);
    }
}

}  // namespace sphere
