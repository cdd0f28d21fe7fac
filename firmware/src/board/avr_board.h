// The Nano's side of SphereDevice: UART frames, EEPROM, the D13 timing pin / LED, the ADXL345's INT1
// on D2, the 200 Hz sample clock on Timer1, and the watchdog (a restart, never a watchdog reset).
#pragma once
#include <stdint.h>

#include "avr_twi.h"
#include "sphere_device.h"

class AvrBoard : public sphere::DeviceHal {
public:
    static const uint8_t TIMING_PIN = 13;  // PB5, the on-board LED: high during the MARG update
    static const uint8_t ADXL_INT_PIN = 2;  // INT0

    explicit AvrBoard(AvrTwi& twi) : twi_(twi) {}
    void begin();                 // pins, INT0, Timer1 at 200 Hz
    static uint8_t takeTicks();   // periods elapsed since the last call (normally 1)
    void service();               // LED blinking for IDENTIFY, reboot once the reply is out
    // Sleeps until the next interrupt (timer, UART, INT0) unless a period or a received byte already waits.
    static void idle();
    void blink(uint8_t times);    // 60 ms blinks at power-up (before the sample clock runs)
    // The watchdog in interrupt mode, 0.25 s: a main loop that stops calling wdt_reset() for that long is
    // restarted from the reset vector (no watchdog reset: avr_board.cpp says why)
    static void startWatchdog();

    uint32_t micros() override;
    bool send(const uint8_t* frame, uint8_t len) override;
    uint8_t txRoom() override;
    uint8_t resetCause() override;
    sphere::KeptBias& keptBias() override;
    void eepromRead(uint16_t addr, uint8_t* out, uint8_t len) override;
    bool eepromReady() override;
    bool eepromWriteByte(uint16_t addr, uint8_t value) override;
    void margPin(bool high) override;
    bool adxlInterrupt(uint32_t& t_us) override;
    void identify(uint8_t seconds) override;
    void reboot() override { reboot_pending_ = true; }
    void setBaud(uint32_t baud) override;
    uint16_t i2cRecoveries() override { return twi_.recoveries(); }
    uint16_t batteryMv() override { return 0; }

private:
    AvrTwi& twi_;
    uint32_t identify_until_ms_ = 0;
    bool identifying_ = false;
    bool reboot_pending_ = false;
    bool fast_link_ = false;  // 500k or 1M baud: margPin lets the transmit ring out first
};
