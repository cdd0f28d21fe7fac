// MARG sphere firmware for the Arduino Nano (ATmega328P, 16 MHz).
// Sensors: ADXL345 (0x53), ITG-3200 (0x68/0x69), HMC5883L (0x1E) or QMC5883L (0x0D) on I²C at 348 kHz; ADXL345 INT1 on D2.
// Output: framed packets per protocol/spec.md on the UART at 115200 baud (SET_BAUD moves a USB link to 250k-1M
// baud while the host confirms it, spec §5.4). D13 is high exactly while
// the MARG update runs. All behaviour lives in src/core/ (SphereDevice); this file only wires the
// Nano's peripherals to it and paces it with the 200 Hz timer.
#include <Arduino.h>
#include <avr/wdt.h>

#include "board/avr_board.h"
#include "board/avr_twi.h"
#include "core/sphere_device.h"

static AvrTwi twi;
static AvrBoard board(twi);
static sphere::SphereDevice device(twi, board);

void setup() {
    // MCUSR (the reset cause) was read and cleared, and the watchdog stopped, in .init3 (avr_board.cpp)
    Serial.begin(115200);
    Serial.write((uint8_t)0);  // at once: ends a frame a reset cut off, so the host drops it now, not 0.25 s later
    board.blink(2);      // power-up: two short blinks
    twi.begin();
    twi.clearBus();      // a sensor left holding SDA by a reset mid-read lets go
    device.begin();      // probes the sensors, loads the calibration, sends 0x00 and HELLO
    board.begin();       // sample clock starts now
    AvrBoard::startWatchdog();  // interrupt mode: a stalled loop restarts the firmware (avr_board.cpp)
}

void loop() {
    // a command whose reply does not fit the transmit buffer yet stays in the receive buffer
    while (Serial.available() > 0 && device.receive((uint8_t)Serial.peek())) Serial.read();
    uint8_t ticks = AvrBoard::takeTicks();
    if (ticks) {
        if (ticks > 1) device.noteOverruns((uint16_t)(ticks - 1));
        device.tick();
        wdt_reset();
    }
    board.service();
    AvrBoard::idle();  // until the next interrupt
}
