#include "avr_twi.h"

#include <avr/io.h>
#include <util/delay.h>
#include <util/twi.h>

namespace {
// One byte at 348 kHz is 25.9 µs = 414 CPU cycles; a polling pass is about 6 cycles. 1500 passes
// (≈ 0.6 ms) leave room for clock stretching and still keep a stalled bus far from the 5 ms period.
const uint16_t WAIT_PASSES = 1500;
const uint8_t SDA_BIT = PC4, SCL_BIT = PC5;  // A4, A5 on the Nano
// SCL = F_CPU / (16 + 2·TWBR) with the prescaler at 1 ("TWI Bit Rate Generator Unit"). Fast mode asks for an
// SCL low time of at least 1.3 µs (the ATmega328P's "2-wire Serial Interface Characteristics", t_LOW; the
// ADXL345's, ITG-3200's and HMC5883L's I²C timing tables alike), and the ATmega's TWI drives SCL low for half
// the period less two CPU cycles (that table's notes): TWBR 12 (400 kHz) gives 18 cycles = 1.125 µs, too short;
// TWBR 15 (347.8 kHz) gives 21 cycles = 1.3125 µs.
const uint8_t TWBR_FAST = 15;
}  // namespace

void AvrTwi::begin() {
    // No internal pull-ups: the sensor boards pull SDA and SCL up to their 3.3 V, and the ATmega's 20-50 kΩ to
    // 5 V beside them would lift the idle bus above the sensors' limit (the ADXL345's absolute maximum on a
    // digital pin is VDD I/O + 0.3 V)
    PORTC &= (uint8_t)~(_BV(SDA_BIT) | _BV(SCL_BIT));
    TWSR = 0;  // prescaler 1
    TWBR = TWBR_FAST;
    TWCR = _BV(TWEN);
}

bool AvrTwi::wait() {
    for (uint16_t i = 0; i < WAIT_PASSES; ++i)
        if (TWCR & _BV(TWINT)) return true;
    return false;
}

bool AvrTwi::command(uint8_t twcr) {
    TWCR = twcr;
    if (wait()) return true;
    recover();
    return false;
}

void AvrTwi::stop() {
    TWCR = _BV(TWINT) | _BV(TWEN) | _BV(TWSTO);
    for (uint16_t i = 0; i < WAIT_PASSES; ++i)
        if (!(TWCR & _BV(TWSTO))) return;
    recover();
}

void AvrTwi::recover() {
    ++recoveries_;
    clearBus();
}

// Open drain by hand: a line is pulled low by making its pin an output with the port bit already 0, and let go by
// making it an input again (the board's pull-ups raise it). The port bits stay 0 throughout, so neither pin is
// ever driven high nor pulled up to 5 V, not even for the instant between two register writes.
void AvrTwi::clearBus() {
    PORTC &= (uint8_t)~(_BV(SDA_BIT) | _BV(SCL_BIT));  // first: low when driven, no pull-up when released
    TWCR = 0;                                          // release the pins to the port: both inputs
    DDRC &= (uint8_t)~(_BV(SDA_BIT) | _BV(SCL_BIT));
    _delay_us(5);
    // clock out whatever a slave still holds: up to nine SCL pulses while SDA is low
    for (uint8_t i = 0; i < 9 && !(PINC & _BV(SDA_BIT)); ++i) {
        DDRC |= _BV(SCL_BIT);  // SCL low
        _delay_us(5);
        DDRC &= (uint8_t)~_BV(SCL_BIT);  // SCL released
        _delay_us(5);
    }
    // STOP by hand: SDA low, then released while SCL is high
    DDRC |= _BV(SDA_BIT);
    _delay_us(5);
    DDRC &= (uint8_t)~_BV(SDA_BIT);
    _delay_us(5);
    TWCR = _BV(TWEN);
}

bool AvrTwi::startAndAddress(uint8_t sla, uint8_t expect_start, uint8_t expect_ack) {
    if (!command(_BV(TWINT) | _BV(TWSTA) | _BV(TWEN))) return false;
    uint8_t st = TW_STATUS;
    if (st != expect_start && st != TW_START && st != TW_REP_START) {
        if (st == TW_BUS_ERROR) recover();
        return false;
    }
    TWDR = sla;
    if (!command(_BV(TWINT) | _BV(TWEN))) return false;
    if (TW_STATUS != expect_ack) {  // NACK: the chip is not there or busy
        stop();
        return false;
    }
    return true;
}

bool AvrTwi::writeRegisters(uint8_t addr, uint8_t reg, const uint8_t* data, uint8_t len) {
    if (!startAndAddress((uint8_t)(addr << 1), TW_START, TW_MT_SLA_ACK)) return false;
    for (int16_t i = -1; i < (int16_t)len; ++i) {
        TWDR = i < 0 ? reg : data[i];
        if (!command(_BV(TWINT) | _BV(TWEN))) return false;
        if (TW_STATUS != TW_MT_DATA_ACK) {
            stop();
            return false;
        }
    }
    stop();
    return true;
}

bool AvrTwi::readRegisters(uint8_t addr, uint8_t reg, uint8_t* out, uint8_t len) {
    if (!startAndAddress((uint8_t)(addr << 1), TW_START, TW_MT_SLA_ACK)) return false;
    TWDR = reg;
    if (!command(_BV(TWINT) | _BV(TWEN))) return false;
    if (TW_STATUS != TW_MT_DATA_ACK) {
        stop();
        return false;
    }
    if (!startAndAddress((uint8_t)((addr << 1) | 1), TW_REP_START, TW_MR_SLA_ACK)) return false;
    for (uint8_t i = 0; i < len; ++i) {
        bool last = i + 1 == len;
        if (!command(last ? (_BV(TWINT) | _BV(TWEN)) : (_BV(TWINT) | _BV(TWEN) | _BV(TWEA)))) return false;
        if (TW_STATUS != (last ? TW_MR_DATA_NACK : TW_MR_DATA_ACK)) {
            stop();
            return false;
        }
        out[i] = TWDR;
    }
    stop();
    return true;
}
