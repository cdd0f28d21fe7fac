// MARG sphere firmware for the Arduino Nano (ATmega328P, 16 MHz).
// Sensors: ADXL345 (0x53), ITG-3200 (0x68/0x69), HMC5883L (0x1E) on I²C at 400 kHz; ADXL345 INT1 on D2.
// Output: framed packets per protocol/spec.md on the UART at 115200 baud. D13 is high exactly while
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
    MCUSR = 0;  // a watchdog reset leaves WDRF set; clear it so the watchdog does not fire again
    wdt_disable();
    Serial.begin(115200);
    board.blink(2);      // power-up: two short blinks
    twi.begin();
    device.begin();      // probes the sensors, loads the calibration, sends 0x00 and HELLO
    board.begin();       // sample clock starts now
    wdt_enable(WDTO_250MS);
}

void loop() {
    while (Serial.available() > 0) device.receive((uint8_t)Serial.read());
    uint8_t ticks = AvrBoard::takeTicks();
    if (ticks) {
        if (ticks > 1) device.noteOverruns((uint16_t)(ticks - 1));
        device.tick();
        wdt_reset();
    }
    board.service();
}
