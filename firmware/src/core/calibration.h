// Calibration: the 42-byte block of protocol/spec.md §5.2, its application to raw samples, and the
// EEPROM image (format version byte, block, CRC-16/CCITT-FALSE over version + block).
#pragma once
#include <stdint.h>

namespace sphere {

const uint8_t CALIBRATION_BLOCK_LEN = 42;
const uint8_t CALIBRATION_EEPROM_VERSION = 1;
const uint8_t CALIBRATION_EEPROM_LEN = 1 + CALIBRATION_BLOCK_LEN + 2;  // version, block, crc (LE)
const int16_t Q14_ONE = 16384;

struct __attribute__((packed)) Calibration {
    int16_t gyro_bias[3];      // gyroscope LSB
    int16_t accel_offset[3];   // accelerometer LSB
    int16_t accel_scale[3];    // Q14
    int16_t mag_offset[3];     // magnetometer LSB (hard iron)
    int16_t mag_soft_iron[9];  // Q14, row-major

    void setDefaults();
    bool accelIsDefault() const;
    bool magIsDefault() const;
    bool gyroIsDefault() const;
    // The ranges of protocol/spec.md §5.2: |gyro_bias| ≤ 1000, |accel_offset| ≤ 512, accel_scale
    // 0.5 … 2.0, |mag_offset| ≤ 2048, |det mag_soft_iron| ≥ 1/16.
    bool valid() const;
};

// The struct is the block: 21 little-endian int16 in the order of §5.2 (little-endian targets only).
static_assert(sizeof(Calibration) == CALIBRATION_BLOCK_LEN, "calibration block is 42 bytes");

void writeCalibrationBlock(const Calibration& c, uint8_t* out);  // 42 bytes, little-endian
void readCalibrationBlock(const uint8_t* in, Calibration& c);

// EEPROM image of CALIBRATION_EEPROM_LEN bytes.
void writeCalibrationImage(const Calibration& c, uint8_t* image);
// True and `c` filled when the image has the right version and CRC and valid values; otherwise false
// and `c` untouched.
bool readCalibrationImage(const uint8_t* image, Calibration& c);

// Applying the calibration (spec §5.2). Results saturate to int16.
void applyGyro(const Calibration& c, const int16_t raw[3], int16_t out[3]);
void applyAccel(const Calibration& c, const int16_t raw[3], int16_t out[3]);
void applyMag(const Calibration& c, const int16_t raw[3], int16_t out[3]);

int16_t saturate16(int32_t v);

}  // namespace sphere
