// probe.cpp - a bench I2C master for the virtual board's own chip tests (not the sphere's firmware).
// Part of the MARG sphere's virtual board (hardware/sim); GPL-3.0-or-later like the board.
//
// Takes text commands on the UART (the board's --send), one per line, runs them over Wire at 400 kHz
// and prints one line per result: "<micros> <tag> <hex bytes or NACK>". Hex numbers throughout.
//   w AA RR VV              write VV to register RR of the chip at 7-bit address AA       -> "w ok|NACK"
//   r AA RR N               burst read of N bytes from RR                                  -> "r xx xx .."
//   p AA RR N PERIOD COUNT  COUNT burst reads, one every PERIOD microseconds (decimal)      -> COUNT "p" lines
//   f AA RR MASK COUNT      COUNT one-byte reads as fast as the bus allows, kept in RAM and printed after:
//                           one "f" line per change of (value & MASK): "<micros> f <value>" (COUNT <= 2000)
//   n AA RR MASK MS         for MS milliseconds, count the reads where (value & MASK) went from 0 to set
//                           -> "n <count> <elapsed us>" (hex count, decimal elapsed)
//   d AA RR N MS            for MS milliseconds, burst-read N bytes (<= 16) as fast as the bus allows and count
//                           the reads that differ from the one before -> "d <count> <elapsed us>"
//   e PIN 00 00 MS          record the level changes of digital pin PIN (hex) for MS ms (decimal), printed
//                           after: one "<micros> e <level>" line each (at most 100)
//   W                       the watchdog at 15 ms, then hang: a watchdog reset
//   I                       the watchdog in interrupt and system reset mode (WDE and WDIE) at 15 ms, then hang with
//                           interrupts off, so its interrupt is never executed                  -> "I"
//   M VV                    write VV to MCUSR, then read it                                     -> "M <MCUSR>"
//   x AAAA VV               write VV to EEPROM byte AAAA (erase and write), time the busy flag (EEPE) and read
//                           the byte back                                 -> "x <busy us, decimal> <byte>"
//   c                       bus clear: TWI off, nine SCL pulses and a STOP on the pins, TWI on -> "c"
//   k                       leave MCUSR as it is at the next start (do not clear it)         -> "k"
// At every start it prints "<micros> probe <MCUSR> <m0> <m1> <m2> <m3>": the reset flags as the program found
// them, and four bytes of .noinit SRAM (which neither the C start-up nor a reset writes) as they were, then
// writes 5a a5 c3 3c there, so the next start shows whether SRAM was kept over the reset. It then clears
// MCUSR, unless told by `k` (kept in .noinit) not to, once.
#include <Arduino.h>
#include <avr/eeprom.h>
#include <avr/wdt.h>
#include <Wire.h>
#include "../sketch_wire.h"

static uint8_t mark[4] __attribute__((section(".noinit")));
static uint8_t keep_mcusr __attribute__((section(".noinit")));  // 0x4b: `k` was sent before this start
static char line[64];
static uint8_t len;

static void hex(uint8_t v) {
  const char *d = "0123456789abcdef";
  Serial.write(d[v >> 4]); Serial.write(d[v & 15]);
}


static void report_read(const char *tag, uint32_t t, bool ok, const uint8_t *b, uint8_t n) {
  Serial.print(t); Serial.write(' '); Serial.print(tag);
  if (!ok) Serial.print(" NACK");
  else for (uint8_t i = 0; i < n; i++) { Serial.write(' '); hex(b[i]); }
  Serial.write('\n');
}

static void bus_clear() {
  TWCR = 0;                       // TWI off: the pins are ours
  pinMode(SDA, INPUT_PULLUP);
  for (uint8_t i = 0; i < 9; i++) {  // open drain: low = output 0, high = released (pull-up)
    pinMode(SCL, OUTPUT); digitalWrite(SCL, LOW); delayMicroseconds(5);
    pinMode(SCL, INPUT_PULLUP); delayMicroseconds(5);
  }
  pinMode(SDA, OUTPUT); digitalWrite(SDA, LOW); delayMicroseconds(5);  // STOP: SDA rises while SCL high
  pinMode(SDA, INPUT_PULLUP);
  Wire.begin(); Wire.setClock(400000); Wire.setWireTimeout(3000, true);
}

static void run(char *s) {
  unsigned long v[6] = {0};
  uint8_t n = 0;
  char cmd = s[0];
  char *p = s + 1;
  while (n < 6) {
    while (*p == ' ') p++;
    if (!*p) break;
    char *end;
    v[n] = strtoul(p, &end, n >= 3 ? 10 : 16);
    if (end == p) break;
    n++;
    p = end;
  }
  uint8_t b[16];
  if (cmd == 'w' && n == 3) {
    Wire.beginTransmission((uint8_t)v[0]); Wire.write((uint8_t)v[1]); Wire.write((uint8_t)v[2]);
    bool ok = Wire.endTransmission() == 0;
    Serial.print(micros()); Serial.print(ok ? " w ok\n" : " w NACK\n");
  } else if (cmd == 'r' && n == 3) {
    uint8_t k = v[2] > 16 ? 16 : v[2];
    uint32_t t = micros();
    report_read("r", t, rd(v[0], v[1], b, k), b, k);
  } else if (cmd == 'p' && n == 5) {
    uint8_t k = v[2] > 16 ? 16 : v[2];
    uint32_t t0 = micros();
    for (unsigned long i = 0; i < v[4]; i++) {
      while ((uint32_t)(micros() - t0) < i * v[3]) {}
      uint32_t t = micros();
      report_read("p", t, rd(v[0], v[1], b, k), b, k);
    }
  } else if (cmd == 'f' && n == 4) {
    static uint32_t ts[120];
    static uint8_t vs[120];
    uint8_t k = 0, last = 0xFF, mask = (uint8_t)v[2];
    for (unsigned long i = 0; i < v[3] && k < 120; i++) {
      uint32_t t = micros();
      if (!rd(v[0], v[1], b, 1)) continue;
      if ((b[0] & mask) != last) { last = b[0] & mask; ts[k] = t; vs[k++] = b[0]; }
    }
    for (uint8_t i = 0; i < k; i++) report_read("f", ts[i], true, vs + i, 1);
  } else if (cmd == 'n' && n == 4) {
    uint8_t mask = (uint8_t)v[2], prev = 1;
    uint16_t count = 0;
    uint32_t t0 = micros(), t = t0;
    while ((uint32_t)(t - t0) < v[3] * 1000UL) {
      if (rd(v[0], v[1], b, 1)) {
        uint8_t set = (b[0] & mask) != 0;
        if (set && !prev) count++;
        prev = set;
      }
      t = micros();
    }
    Serial.print(micros()); Serial.print(" n "); hex(count >> 8); hex(count & 0xFF);
    Serial.write(' '); Serial.print(t - t0); Serial.write('\n');
  } else if (cmd == 'd' && n == 4) {
    uint8_t k = v[2] > 16 ? 16 : v[2], last[16];
    uint16_t count = 0;
    bool have = false;
    uint32_t t0 = micros(), t = t0;
    while ((uint32_t)(t - t0) < v[3] * 1000UL) {
      if (rd(v[0], v[1], b, k)) {
        if (have && memcmp(b, last, k)) count++;
        memcpy(last, b, k);
        have = true;
      }
      t = micros();
    }
    Serial.print(micros()); Serial.print(" d "); hex(count >> 8); hex(count & 0xFF);
    Serial.write(' '); Serial.print(t - t0); Serial.write('\n');
  } else if (cmd == 'e' && n == 4) {
    static uint32_t ts[100];
    static uint8_t lv[100];
    uint8_t k = 0, pin = (uint8_t)v[0], last = digitalRead(pin);
    uint32_t t0 = micros(), t = t0;
    while ((uint32_t)(t - t0) < v[3] * 1000UL && k < 100) {
      uint8_t now = digitalRead(pin);
      t = micros();
      if (now != last) { ts[k] = t; lv[k++] = now; last = now; }
    }
    for (uint8_t i = 0; i < k; i++) report_read("e", ts[i], true, lv + i, 1);
  } else if (cmd == 'W') {
    Serial.print(micros()); Serial.print(" W\n"); Serial.flush();
    wdt_enable(WDTO_15MS);
    for (;;) {}
  } else if (cmd == 'I') {
    Serial.print(micros()); Serial.print(" I\n"); Serial.flush();
    cli();
    WDTCSR = _BV(WDCE) | _BV(WDE);
    WDTCSR = _BV(WDE) | _BV(WDIE);  // WDP = 0: 2K cycles of the 128 kHz oscillator, 16 ms
    for (;;) {}
  } else if (cmd == 'M' && n == 1) {
    MCUSR = (uint8_t)v[0];
    uint8_t m = MCUSR;
    Serial.print(micros()); Serial.print(" M "); hex(m); Serial.write('\n');
  } else if (cmd == 'x' && n == 2) {
    eeprom_busy_wait();
    EEAR = (uint16_t)v[0];
    EEDR = (uint8_t)v[1];
    EECR = 0;  // EEPM = 00: erase and write
    uint32_t t0 = micros();
    cli();
    EECR |= _BV(EEMPE);
    EECR |= _BV(EEPE);
    sei();
    while (EECR & _BV(EEPE)) {}
    uint32_t busy = micros() - t0;
    uint8_t back = eeprom_read_byte((const uint8_t *)(uint16_t)v[0]);
    Serial.print(micros()); Serial.print(" x "); Serial.print(busy); Serial.write(' '); hex(back); Serial.write('\n');
  } else if (cmd == 'k') {
    keep_mcusr = 0x4b;
    Serial.print(micros()); Serial.print(" k\n");
  } else if (cmd == 'c') {
    bus_clear();
    Serial.print(micros()); Serial.print(" c\n");
  } else {
    Serial.print(micros()); Serial.print(" ? "); Serial.print(s); Serial.write('\n');
  }
}

void setup() {
  uint8_t cause = MCUSR;
  if (keep_mcusr != 0x4b) {
    MCUSR = 0;
    wdt_disable();  // a watchdog reset leaves the watchdog on (WDRF)
  }
  keep_mcusr = 0;
  Serial.begin(115200);
  Wire.begin(); Wire.setClock(400000); Wire.setWireTimeout(3000, true);
  Serial.print(micros()); Serial.print(" probe "); hex(cause);
  static const uint8_t pattern[4] = {0x5a, 0xa5, 0xc3, 0x3c};
  for (uint8_t i = 0; i < 4; i++) { Serial.write(' '); hex(mark[i]); mark[i] = pattern[i]; }
  Serial.write('\n');
}

void loop() {
  while (Serial.available()) {
    char c = Serial.read();
    if (c == '\n' || c == '\r') {
      if (len) { line[len] = 0; run(line); len = 0; }
    } else if (len < sizeof line - 1) line[len++] = c;
  }
}
