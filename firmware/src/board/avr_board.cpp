#include "avr_board.h"

#include <Arduino.h>
#include <avr/eeprom.h>
#include <avr/interrupt.h>
#include <avr/sleep.h>
#include <avr/wdt.h>
#include <util/atomic.h>
#include <util/delay.h>

// Why the chip (or the firmware) last started, for HELLO reset_cause. MCUSR is read and cleared in .init3,
// before main() and the Arduino core run, and the watchdog stopped there. What the Nano's boot loaders leave
// in MCUSR (hardware/sim/README.md, "Boot loaders"): ATmegaBOOT leaves it as the reset set it; Optiboot 8
// leaves it (but WDRF when EXTRF is set: its own time-out) and hands it over in r2 as well; Optiboot 4.4,
// the Nano's, clears it and hands nothing over (r2 then holds whatever the last program left there). So
// MCUSR is the only source: flags found there are the reset's; none found means a boot loader cleared them,
// and the cause is reported as 0, unknown, rather than guessed. The firmware's own restarts (its watchdog's
// interrupt, REBOOT) leave a mark in .noinit RAM and report the watchdog bit.
static uint8_t g_reset_cause __attribute__((section(".noinit")));
static uint8_t g_restart_mark[2] __attribute__((section(".noinit")));  // RESET_WATCHDOG and its complement
extern "C" void captureResetCause() __attribute__((naked, used, section(".init3")));
extern "C" void captureResetCause() {
    uint8_t m = MCUSR;
    MCUSR = 0;  // a watchdog reset leaves WDRF set, which keeps the watchdog on: clear it, then stop it
    wdt_disable();
    uint8_t cause = (uint8_t)(m & 0x0F);
    if (!cause && g_restart_mark[0] == sphere::RESET_WATCHDOG && g_restart_mark[1] == (uint8_t)~sphere::RESET_WATCHDOG)
        cause = sphere::RESET_WATCHDOG;
    g_restart_mark[0] = 0;
    g_reset_cause = cause;
}

// Starts the firmware again from its reset vector without a reset. A watchdog *reset* is not used: after one
// the Nano's old bootloader (ATmegaBOOT, which leaves the watchdog on at 16 ms while WDRF is set) resets the
// chip again before it reaches the program, for good (Arduino issue 4492), and the firmware cannot tell which
// boot loader it sits behind (the Nano's lock bits keep the boot section from being read). The registers the
// firmware and the Arduino core set are put back to their reset values ("Register Summary"), the pins to
// inputs without pull-ups; the C start-up sets the stack pointer and SREG, and .init3 reads the mark.
static void restartFirmware() __attribute__((noreturn));
static void restartFirmware() {
    cli();
    wdt_disable();
    g_restart_mark[0] = sphere::RESET_WATCHDOG;
    g_restart_mark[1] = (uint8_t)~sphere::RESET_WATCHDOG;
    TWCR = 0;
    UCSR0B = 0;
    UCSR0A = 0;
    TIMSK0 = TIMSK1 = TIMSK2 = 0;
    TCCR0A = TCCR0B = TCCR1A = TCCR1B = TCCR2A = TCCR2B = 0;
    TIFR0 = TIFR1 = TIFR2 = 0xFF;  // flags are cleared by writing one
    EIMSK = 0;
    EICRA = 0;
    EIFR = 0xFF;
    PCICR = 0;
    PCIFR = 0xFF;
    ADCSRA = 0;
    DDRB = DDRC = DDRD = 0;
    PORTB = PORTC = PORTD = 0;
    asm volatile("jmp 0");
    __builtin_unreachable();
}

// The watchdog's time-out in interrupt mode (WDIE without WDE, "Watchdog Timer Configuration"): the main loop
// stopped resetting it for 250 ms, and this restarts the firmware. A hang with interrupts off is not caught
// (it would need the system reset mode, which the old bootloader cannot take).
ISR(WDT_vect) { restartFirmware(); }

void AvrBoard::startWatchdog() {
    ATOMIC_BLOCK(ATOMIC_RESTORESTATE) {
        wdt_reset();
        WDTCSR = _BV(WDCE) | _BV(WDE);  // the timed sequence: the prescaler changes only within four cycles
        WDTCSR = _BV(WDIE) | _BV(WDP2);  // interrupt mode, 32K cycles of the 128 kHz oscillator: 0.25 s
    }
}

namespace {
volatile uint8_t g_ticks = 0;
volatile bool g_int_seen = false;
volatile uint32_t g_int_t_us = 0;

}  // namespace

// ADXL345 INT1 on D2 (INT0), rising edge: note when it was seen; the loop reads INT_SOURCE
ISR(INT0_vect) {
    if (!g_int_seen) {
        g_int_t_us = ::micros();
        g_int_seen = true;
    }
}

ISR(TIMER1_COMPA_vect) {
    if (g_ticks < 255) ++g_ticks;
}

void AvrBoard::begin() {
    DDRB |= _BV(PB5);  // D13 output, low
    PORTB &= (uint8_t)~_BV(PB5);
    DDRD &= (uint8_t)~_BV(PD2);  // D2 input, no pull-up (the ADXL345 drives INT1 push-pull)
    PORTD &= (uint8_t)~_BV(PD2);
    EICRA = (uint8_t)((EICRA & ~(_BV(ISC01) | _BV(ISC00))) | _BV(ISC01) | _BV(ISC00));  // rising edge
    EIFR = _BV(INTF0);
    EIMSK |= _BV(INT0);
    // Timer1, CTC on OCR1A, clk/8: 16 MHz / 8 / 10000 = 200 Hz
    ATOMIC_BLOCK(ATOMIC_RESTORESTATE) {
        TCCR1A = 0;
        TCCR1B = _BV(WGM12) | _BV(CS11);
        TCNT1 = 0;
        OCR1A = (uint16_t)(F_CPU / 8 / 200 - 1);
        TIFR1 = _BV(OCF1A);
        TIMSK1 = _BV(OCIE1A);
        g_ticks = 0;
    }
}

uint8_t AvrBoard::takeTicks() {
    uint8_t n;
    ATOMIC_BLOCK(ATOMIC_RESTORESTATE) {
        n = g_ticks;
        g_ticks = 0;
    }
    return n;
}

// Idle sleep (datasheet §10.1 Sleep Modes: "Idle mode stops the CPU but allows ... USART, ... Timer/Counters,
// ... and the interrupt system to continue operating"): the loop has nothing to do until an interrupt sets a
// flag (the 200 Hz tick, a received byte, a transmitted one, INT0, timer0's millis), and every one of those
// wakes it. Checked with interrupts off and slept with `sei; sleep` (the instruction after sei runs before
// any interrupt), so a tick that comes between the check and the sleep wakes it at once. Saves the CPU's
// idle current on a Nano; the virtual board skips the cycles the AVR sleeps.
void AvrBoard::idle() {
    set_sleep_mode(SLEEP_MODE_IDLE);
    cli();
    if (!g_ticks && !Serial.available()) {
        sleep_enable();
        sei();
        sleep_cpu();
        sleep_disable();
    }
    sei();
}

uint32_t AvrBoard::micros() { return ::micros(); }

bool AvrBoard::send(const uint8_t* frame, uint8_t len) {
    if (Serial.availableForWrite() < (int)len) return false;
    Serial.write(frame, len);
    return true;
}

void AvrBoard::setBaud(uint32_t baud) {
    Serial.flush();     // the REPLY (and anything before it) leaves at the old rate
    Serial.begin(baud);  // 250k, 500k, 1M: UBRR 7, 3, 1 with U2X, exact on 16 MHz (ATmega328P datasheet, Table 20-7)
    fast_link_ = baud >= 500000;
}

uint8_t AvrBoard::txRoom() {
    int n = Serial.availableForWrite();
    return (uint8_t)(n > 255 ? 255 : n);
}

uint8_t AvrBoard::resetCause() { return g_reset_cause; }

// The gyro bias kept over a reset that is not a power-on: the C start-up leaves .noinit as the last program
// run left it (SphereDevice::begin decides by the reset cause and the record's check word whether to use it).
static sphere::KeptBias g_kept_bias __attribute__((section(".noinit")));
sphere::KeptBias& AvrBoard::keptBias() { return g_kept_bias; }

void AvrBoard::eepromRead(uint16_t addr, uint8_t* out, uint8_t len) {
    eeprom_read_block(out, (const void*)addr, len);
}

bool AvrBoard::eepromReady() { return eeprom_is_ready(); }

bool AvrBoard::eepromWriteByte(uint16_t addr, uint8_t value) {
    if (!eeprom_is_ready()) return false;
    eeprom_write_byte((uint8_t*)addr, value);  // starts the write (EEMPE, EEPE) and returns: EEPE stays set 3.4 ms
    return true;  // SphereDevice reads the block back to verify
}

void AvrBoard::margPin(bool high) {
    // While the update runs, the UART's transmit interrupt is held back, so the update is not stretched
    // by it and the pulse measures the update (Timer0's 1 kHz tick for micros() may still fall inside:
    // about 80 cycles). The UART meanwhile finishes the byte in its shift register; receive and the
    // ADXL345's INT0 stay enabled. Both steps are atomic, and the interrupt comes back only when the
    // transmit buffer holds bytes: the core's interrupt switches itself off when the buffer runs empty,
    // and switching it on over an empty buffer would send the whole stale ring again.
    // On a fast link (500k, 1M) the ring is first let out: it holds the period's RAW_SAMPLE, sent just before
    // (SphereDevice::tick), which would otherwise stop after its first bytes for the whole update; at 1 Mbaud that
    // is 0.3 ms of waiting (the ring's 127 bytes at 500k: 2.5 ms, inside the 5 ms period). At 115200 the frame
    // takes 2.5 ms by itself and the update's 0.6 ms pause in it is left.
    if (high)
        while (fast_link_ && Serial.availableForWrite() < SERIAL_TX_BUFFER_SIZE - 1) {
        }
    ATOMIC_BLOCK(ATOMIC_RESTORESTATE) {
        if (high) {
            UCSR0B &= (uint8_t)~_BV(UDRIE0);
            if (!identifying_) PORTB |= _BV(PB5);
        } else {
            if (!identifying_) PORTB &= (uint8_t)~_BV(PB5);
            if (Serial.availableForWrite() < SERIAL_TX_BUFFER_SIZE - 1) UCSR0B |= _BV(UDRIE0);
        }
    }
}

bool AvrBoard::adxlInterrupt(uint32_t& t_us) {
    bool seen;
    ATOMIC_BLOCK(ATOMIC_RESTORESTATE) {
        seen = g_int_seen;
        t_us = g_int_t_us;
        g_int_seen = false;
    }
    if (!seen && (PIND & _BV(PD2))) {  // latched before the edge could be seen
        t_us = ::micros();
        seen = true;
    }
    return seen;
}

void AvrBoard::identify(uint8_t seconds) {
    identifying_ = true;
    identify_until_ms_ = millis() + 1000UL * seconds;
}

void AvrBoard::blink(uint8_t times) {
    DDRB |= _BV(PB5);
    for (uint8_t i = 0; i < times; ++i) {
        PORTB |= _BV(PB5);
        _delay_ms(60);
        PORTB &= (uint8_t)~_BV(PB5);
        _delay_ms(60);
    }
}

void AvrBoard::service() {
    if (identifying_) {
        uint32_t now = millis();
        if ((int32_t)(now - identify_until_ms_) >= 0) {
            identifying_ = false;
            PORTB &= (uint8_t)~_BV(PB5);
        } else if ((now / 100) & 1) {
            PORTB |= _BV(PB5);  // 5 Hz
        } else {
            PORTB &= (uint8_t)~_BV(PB5);
        }
    }
    if (reboot_pending_) {
        Serial.flush();  // the REPLY is on the wire
        restartFirmware();
    }
}
