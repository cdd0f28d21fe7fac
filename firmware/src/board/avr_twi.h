// Polled TWI (I²C) master for the ATmega328P at 348 kHz (fast mode's SCL low time) with bounded waits: no transaction can hang
// the sample loop. A wait that runs out, or a bus error, triggers a bus recovery (nine SCL pulses
// and a STOP by hand, then the TWI is re-enabled), counted in recoveries().
#pragma once
#include <stdint.h>

#include "i2c_bus.h"

class AvrTwi : public sphere::I2cBus {
public:
    void begin();
    bool writeRegisters(uint8_t addr, uint8_t reg, const uint8_t* data, uint8_t len) override;
    bool readRegisters(uint8_t addr, uint8_t reg, uint8_t* out, uint8_t len) override;
    uint16_t recoveries() const { return recoveries_; }
    void recover();   // clearBus(), counted in recoveries()
    // Up to nine SCL pulses while a slave holds SDA low (one left mid-read by a reset), then a STOP;
    // the TWI is enabled again. Run once at power-up before the sensors are probed.
    void clearBus();

private:
    bool wait();                 // TWINT within the bound
    bool command(uint8_t twcr);  // sets TWCR and waits
    bool startAndAddress(uint8_t sla, uint8_t expect_start, uint8_t expect_ack);
    void stop();
    uint16_t recoveries_ = 0;
};
