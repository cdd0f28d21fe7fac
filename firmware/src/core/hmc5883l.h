// HMC5883L magnetometer (Honeywell) at 0x1E: continuous mode at its 75 Hz maximum, one sample
// averaged, gain 1 (±1.3 Ga, 1090 LSB/gauss). Data registers are big-endian in the order X, Z, Y;
// −4096 on an axis means it overflowed.
#pragma once
#include <stdint.h>

#include "i2c_bus.h"

namespace sphere {

class Hmc5883l {
public:
    static const uint8_t ADDRESS = 0x1E;
    enum Reg : uint8_t { CONFIG_A = 0x00, CONFIG_B = 0x01, MODE = 0x02, DATA_X_MSB = 0x03, STATUS = 0x09, ID_A = 0x0A };
    static const uint8_t CONFIG_A_75HZ = 0x18;  // 1 sample, 75 Hz, normal measurement
    static const uint8_t CONFIG_B_GAIN1 = 0x20;  // ±1.3 Ga, 1090 LSB/gauss
    static const uint8_t MODE_CONTINUOUS = 0x00;
    static const uint8_t STATUS_RDY = 0x01;
    static const int16_t OVERFLOW = -4096;

    // Polls without RDY before the data are read anyway (4 × 5 ms > one 13.3 ms output period): a chip
    // or a model whose STATUS never shows RDY still delivers its samples.
    static const uint8_t POLLS_WITHOUT_RDY = 4;

    explicit Hmc5883l(I2cBus& bus) : bus_(bus), idle_polls_(0) { id_[0] = id_[1] = id_[2] = 0; }

    // Reads ID A–C ("H43") and configures the chip when they match.
    bool begin();
    const uint8_t* id() const { return id_; }
    static bool idValid(const uint8_t id[3]) { return id[0] == 'H' && id[1] == '4' && id[2] == '3'; }
    // Reads STATUS; when a new sample is ready (RDY, or POLLS_WITHOUT_RDY polls without it), reads it
    // into `out` (x, y, z) and sets `fresh`. `out` is left as it was otherwise. False on a bus failure.
    bool poll(int16_t out[3], bool& fresh);

    static void decode(const uint8_t raw[6], int16_t out[3]);  // X, Z, Y big-endian → x, y, z

private:
    I2cBus& bus_;
    uint8_t id_[3];
    uint8_t idle_polls_;
};

}  // namespace sphere
