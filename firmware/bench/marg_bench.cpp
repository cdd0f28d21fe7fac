// Cycle count of one MargFilter::update on the ATmega328P, run on simavr (make -C firmware bench).
// Timer1 runs at the CPU clock (prescaler 1); each update is bracketed by two TCNT1 reads and the
// cost of an empty bracket is subtracted. Results go out on the UART, which simavr prints.
#include <avr/interrupt.h>
#include <avr/io.h>
#include <avr/sleep.h>

#include "fixed_math.h"
#include "marg_filter.h"
#include "moving_sample.h"

// simavr prints what the UART sends, a line at a time
static void put(const char* s) {
    while (*s) {
        while (!(UCSR0A & _BV(UDRE0))) {
        }
        UDR0 = (uint8_t)*s++;
    }
}
static void putNum(uint32_t v) {
    char b[11];
    uint8_t i = 10;
    b[i] = 0;
    do {
        b[--i] = (char)('0' + v % 10);
        v /= 10;
    } while (v);
    put(b + i);
}

using sphere::MargFilter;

static MargFilter filter;

struct Stats {
    uint16_t min, max;
    uint32_t sum;
    uint16_t n;
};

static void run(const char* name, bool acc, bool mag, uint16_t overhead) {
    Stats s = {0xFFFF, 0, 0, 0};
    int16_t g[3], a[3], m[3];
    for (uint16_t i = 0; i < 400; ++i) {
        movingSample(i, g, a, m);
        uint16_t t0 = TCNT1;
        filter.update(g, a, m, acc, mag);
        uint16_t t1 = TCNT1;
        uint16_t c = (uint16_t)(t1 - t0 - overhead);
        if (c < s.min) s.min = c;
        if (c > s.max) s.max = c;
        s.sum += c;
        ++s.n;
    }
    put(name);
    put(": cycles per update min ");
    putNum(s.min);
    put(" mean ");
    putNum(s.sum / s.n);
    put(" max ");
    putNum(s.max);
    put(" (n=");
    putNum(s.n);
    put(")\n");
    // the state after the run, for comparison with the same code compiled natively (bench/marg_check.cpp)
    put("  state after run:");
    for (uint8_t i = 0; i < 4; ++i) {
        int32_t q = filter.quaternionQ30()[i];
        put(q < 0 ? " -" : " ");
        putNum(q < 0 ? (uint32_t)(-q) : (uint32_t)q);
    }
    put("\n");
}

int main() {
    UBRR0 = 16;  // 115200 baud with U2X
    UCSR0A = _BV(U2X0);
    UCSR0B = _BV(TXEN0);
    TCCR1A = 0;
    TCCR1B = _BV(CS10);  // clk/1
    volatile uint16_t t0 = TCNT1;
    volatile uint16_t t1 = TCNT1;
    uint16_t overhead = (uint16_t)(t1 - t0);
    put("bench: MargFilter::update on ATmega328P at 16 MHz (timer-read overhead of ");
    putNum(overhead);
    put(" cycles subtracted)\n");
    run("MARG (accel + mag)", true, true, overhead);
    run("IMU (accel only)", true, false, overhead);
    run("gyro only", false, false, overhead);
    filter.begin();
    run("MARG from identity", true, true, overhead);
    {
        int16_t v16[3] = {-120, 37, 251}, o[4];
        int32_t v32[4] = {-1200000l, 370000l, 25100l, 9000000l};
        uint16_t t0 = TCNT1;
        sphere::normaliseQ14(v16, 3, o);
        uint16_t t1 = TCNT1;
        sphere::normaliseQ14(v32, 4, o);
        uint16_t t2 = TCNT1;
        put("normaliseQ14: 3 x int16 ");
        putNum(t1 - t0 - overhead);
        put(" cycles, 4 x int32 ");
        putNum(t2 - t1 - overhead);
        put(" cycles\n");
        volatile uint16_t xin = 30000;
        uint16_t t3 = TCNT1;
        volatile uint16_t r = sphere::invSqrtQ14(xin);
        uint16_t t4 = TCNT1;
        (void)r;
        put("invSqrtQ14: ");
        putNum(t4 - t3 - overhead);
        put(" cycles\n");
    }
    put("bench: done\n");
    while (!(UCSR0A & _BV(TXC0))) {
    }
    cli();
    sleep_cpu();
}
