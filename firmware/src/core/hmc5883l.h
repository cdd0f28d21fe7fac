// HMC5883L magnetometer (Honeywell) at 0x1E: single-measurement mode triggered from the sample
// clock every TRIGGER_TICKS periods (datasheet §"Single-Measurement Mode": one conversion, about 6 ms,
// then idle; up to 160 Hz), one sample averaged, gain 1 (±1.3 Ga, 1090 LSB/gauss). RDY (STATUS bit 0)
// is set once all six data registers hold the new conversion and cleared when the chip starts writing
// the next one, so it is read before the data: a read is fresh only after a trigger and RDY. Data
// registers are big-endian in the order X, Z, Y; −4096 on an axis means it overflowed.
#pragma once
#include <stdint.h>

#include "i2c_bus.h"

namespace sphere {

class Hmc5883l {
public:
    static const uint8_t ADDRESS = 0x1E;
    enum Reg : uint8_t { CONFIG_A = 0x00, CONFIG_B = 0x01, MODE = 0x02, DATA_X_MSB = 0x03, STATUS = 0x09, ID_A = 0x0A };
    static const uint8_t CONFIG_A_75HZ = 0x18;  // 1 sample, normal measurement (rate bits unused in single mode)
    static const uint8_t CONFIG_B_GAIN1 = 0x20;  // ±1.3 Ga, 1090 LSB/gauss
    static const uint8_t MODE_SINGLE = 0x01;
    static const uint8_t STATUS_RDY = 0x01;
    static const int16_t OVERFLOW = -4096;

    // A conversion is triggered every TRIGGER_TICKS sample periods (10 ms: 100 Hz, well past the 6 ms
    // conversion); when RDY is still clear TIMEOUT_TICKS after a trigger (a lost trigger write, a
    // chip reset), the chip is triggered again.
    static const uint8_t TRIGGER_TICKS = 2, TIMEOUT_TICKS = 6;
    static const uint8_t RATE_HZ = 100;

    explicit Hmc5883l(I2cBus& bus) : bus_(bus), since_trigger_(0) { id_[0] = id_[1] = id_[2] = 0; }

    // Reads ID A–C ("H43") and configures the chip when they match.
    bool begin();
    const uint8_t* id() const { return id_; }
    static bool idValid(const uint8_t id[3]) { return id[0] == 'H' && id[1] == '4' && id[2] == '3'; }
    // Called once per sample period. Every TRIGGER_TICKS periods: reads STATUS and, with RDY, the new
    // sample into `out` (x, y, z) and sets `fresh`; then triggers the next conversion. `out` is left as
    // it was otherwise. False on a bus failure (retried the next period).
    bool poll(int16_t out[3], bool& fresh);

    static void decode(const uint8_t raw[6], int16_t out[3]);  // X, Z, Y big-endian → x, y, z

private:
    I2cBus& bus_;
    uint8_t id_[3];
    uint8_t since_trigger_;
};

}  // namespace sphere
