// QMC5883L magnetometer (QST) at 0x0D, the chip many modules sold as "HMC5883L" carry: its own register
// map (datasheet rev. 1.0 §9): data X, Y, Z little-endian at 0x00–0x05, STATUS 0x06 (DRDY bit 0, OVL
// bit 1, DOR bit 2), CONTROL 1 0x09 (mode, ODR, range, oversampling), SET/RESET period 0x0B (0x01
// advised), chip ID 0x0D (0xFF). Run continuous at 100 Hz, ±8 G (3000 LSB/G), 512× oversampling;
// values are converted to the HMC5883L's gain-1 units (1090 LSB/gauss) that RAW_SAMPLE carries.
#pragma once
#include <stdint.h>

#include "i2c_bus.h"

namespace sphere {

class Qmc5883l {
public:
    static const uint8_t ADDRESS = 0x0D;
    enum Reg : uint8_t { DATA_X_LSB = 0x00, STATUS = 0x06, CONTROL_1 = 0x09, SET_RESET = 0x0B, CHIP_ID = 0x0D };
    static const uint8_t CHIP_ID_VALUE = 0xFF;
    static const uint8_t STATUS_DRDY = 0x01, STATUS_OVL = 0x02;
    // OSR 512 (00), RNG 8 G (01), ODR 100 Hz (10), continuous (01)
    static const uint8_t CONTROL_1_100HZ_8G = (0 << 6) | (1 << 4) | (2 << 2) | 1;

    explicit Qmc5883l(I2cBus& bus) : bus_(bus), id_(0) {}
    bool begin();  // reads CHIP_ID and configures the chip when it is 0xFF
    uint8_t id() const { return id_; }
    // Reads STATUS; with DRDY, reads the sample into `out` (gain-1 HMC5883L units; −4096 on every axis
    // on OVL) and sets `fresh`. False on a bus failure.
    bool poll(int16_t out[3], bool& fresh);
    // Little-endian X, Y, Z at 3000 LSB/G → 1090 LSB/gauss.
    static void decode(const uint8_t raw[6], int16_t out[3]);

private:
    I2cBus& bus_;
    uint8_t id_;
};

}  // namespace sphere
