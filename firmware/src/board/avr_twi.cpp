#include "avr_twi.h"

#include <avr/io.h>
#include <util/delay.h>
#include <util/twi.h>

namespace {
// One byte at 400 kHz is 22.5 µs = 360 CPU cycles; a polling pass is about 6 cycles. 1500 passes
// (≈ 0.6 ms) leave room for clock stretching and still keep a stalled bus far from the 5 ms period.
const uint16_t WAIT_PASSES = 1500;
const uint8_t SDA_BIT = PC4, SCL_BIT = PC5;  // A4, A5 on the Nano
}  // namespace

void AvrTwi::begin() {
    PORTC |= _BV(SDA_BIT) | _BV(SCL_BIT);  // internal pull-ups (the breakout boards carry stronger ones)
    TWSR = 0;                              // prescaler 1
    TWBR = (uint8_t)((F_CPU / 400000UL - 16) / 2);
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

void AvrTwi::clearBus() {
    TWCR = 0;  // release the pins to the port
    DDRC &= (uint8_t)~_BV(SDA_BIT);
    PORTC |= _BV(SDA_BIT);
    // clock out whatever a slave still holds: up to nine SCL pulses while SDA is low
    for (uint8_t i = 0; i < 9 && !(PINC & _BV(SDA_BIT)); ++i) {
        DDRC |= _BV(SCL_BIT);
        PORTC &= (uint8_t)~_BV(SCL_BIT);
        _delay_us(5);
        DDRC &= (uint8_t)~_BV(SCL_BIT);
        PORTC |= _BV(SCL_BIT);
        _delay_us(5);
    }
    // STOP by hand: SDA low → high while SCL is high
    DDRC |= _BV(SDA_BIT);
    PORTC &= (uint8_t)~_BV(SDA_BIT);
    _delay_us(5);
    DDRC &= (uint8_t)~_BV(SDA_BIT);
    PORTC |= _BV(SDA_BIT);
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
