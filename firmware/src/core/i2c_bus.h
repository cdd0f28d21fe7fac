// The I²C bus as the drivers see it. The AVR implementation (src/avr/avr_twi.*) has bounded waits
// and bus recovery; the native tests use register-map fakes of the three chips.
#pragma once
#include <stdint.h>

namespace sphere {

class I2cBus {
public:
    // Writes `reg` then `len` bytes. False on NACK, arbitration loss or timeout.
    virtual bool writeRegisters(uint8_t addr, uint8_t reg, const uint8_t* data, uint8_t len) = 0;
    // Writes `reg`, then reads `len` bytes with a repeated start. False on any failure.
    virtual bool readRegisters(uint8_t addr, uint8_t reg, uint8_t* out, uint8_t len) = 0;

    bool writeRegister(uint8_t addr, uint8_t reg, uint8_t value) { return writeRegisters(addr, reg, &value, 1); }
    bool readRegister(uint8_t addr, uint8_t reg, uint8_t& value) { return readRegisters(addr, reg, &value, 1); }
    // Writes `count` register/value pairs in order, one transaction each, from a table declared
    // SPHERE_TABLE (flash_table.h); false at the first that fails.
    bool writeSequence(uint8_t addr, const uint8_t (*pairs)[2], uint8_t count);

protected:
    ~I2cBus() {}
};

}  // namespace sphere
