// testfw.cpp - the virtual board's own test sketch (not the sphere's firmware).
// Part of the MARG sphere's virtual board (hardware/sim); GPL-3.0-or-later like the board.
//
// Reads the three chips' IDs and data at 200 Hz (Timer1 compare interrupt) over Wire and sends protocol/spec.md frames:
// HELLO at start, RAW_SAMPLE every period, EVENT on ADXL345 INT1 (D2), STATUS once a second.
// STATUS rx_errors counts every byte received on the UART (to test the board's --send).
// D13 (PB5) is high during a dummy "update" of a fixed length, so the board's timing is testable.
#include <Arduino.h>
#include <Wire.h>
#include "../sketch_wire.h"

static uint8_t seq;
static uint16_t crc16(const uint8_t *p, uint8_t n) {
  uint16_t c = 0xFFFF;
  while (n--) {
    c ^= (uint16_t)(*p++) << 8;
    for (uint8_t i = 0; i < 8; i++) c = (c & 0x8000) ? (c << 1) ^ 0x1021 : c << 1;
  }
  return c;
}
static void send(uint8_t type, const uint8_t *body, uint8_t n) {
  uint8_t p[64], e[70];
  p[0] = type; p[1] = seq++;
  memcpy(p + 2, body, n);
  uint16_t c = crc16(p, n + 2);
  p[n + 2] = c & 0xFF; p[n + 3] = c >> 8;
  uint8_t len = n + 4, code_i = 0, o = 1, code = 1;
  for (uint8_t i = 0; i < len; i++) {
    if (p[i] == 0) { e[code_i] = code; code_i = o++; code = 1; }
    else { e[o++] = p[i]; code++; }
  }
  e[code_i] = code;
  Serial.write(e, o);
  Serial.write((uint8_t)0);
}
static bool wr(uint8_t a, uint8_t r, uint8_t v) {
  Wire.beginTransmission(a); Wire.write(r); Wire.write(v); return Wire.endTransmission() == 0;
}
static volatile bool int1, tick;
ISR(TIMER1_COMPA_vect) { tick = true; }  // the 200 Hz sample clock
static void on_int1() { int1 = true; }
static uint8_t found, devid, whoami, hid[3];
static uint16_t errs[3], rx_bytes;
static void put16(uint8_t *b, int16_t v) { b[0] = v & 0xFF; b[1] = (uint16_t)v >> 8; }
static void put32(uint8_t *b, uint32_t v) { for (uint8_t i = 0; i < 4; i++) b[i] = v >> (8 * i); }

static void init_chips() {
  wr(0x53, 0x31, 0x0B); wr(0x53, 0x2C, 0x0B); wr(0x53, 0x1D, 48); wr(0x53, 0x21, 16); wr(0x53, 0x22, 80);
  wr(0x53, 0x23, 200); wr(0x53, 0x2A, 0x07); wr(0x53, 0x28, 7); wr(0x53, 0x29, 20);
  wr(0x53, 0x2F, 0x00); wr(0x53, 0x2E, 0x64); wr(0x53, 0x2D, 0x08);
  wr(0x68, 0x3E, 0x01); wr(0x68, 0x15, 4); wr(0x68, 0x16, 0x18 | 3);
  wr(0x1E, 0x00, 0x18); wr(0x1E, 0x01, 0x20); wr(0x1E, 0x02, 0x00);
}

void setup() {
  Serial.begin(115200);
  Serial.write((uint8_t)0);
  pinMode(13, OUTPUT);
  Wire.begin(); Wire.setClock(400000); Wire.setWireTimeout(3000, true);
  if (rd(0x53, 0x00, &devid, 1) && devid == 0xE5) found |= 1;
  if (rd(0x68, 0x00, &whoami, 1) && (whoami & 0x7E) == 0x68) found |= 2;
  if (rd(0x1E, 0x0A, hid, 3) && hid[0] == 'H') found |= 4;
  init_chips();
  uint8_t h[19] = {1, 0, 0, 1, found, devid, whoami, hid[0], hid[1], hid[2], 200, 0, 75, 5, 200, 0, 0, 0, 0};
  send(0x01, h, 19);
  attachInterrupt(digitalPinToInterrupt(2), on_int1, RISING);
  TCCR1A = 0; TCCR1B = _BV(WGM12) | _BV(CS11); OCR1A = 9999; TIMSK1 = _BV(OCIE1A);  // 16 MHz / 8 / 10000
}

static uint32_t last_status;
static uint8_t ok;
void loop() {
  while (!tick) {}
  tick = false;
  uint32_t t = micros();
  uint8_t a[6] = {0}, g[6] = {0}, m[6] = {0}, f = 0;
  if (rd(0x53, 0x32, a, 6)) f |= 1; else errs[0]++;
  if (rd(0x68, 0x1D, g, 6)) f |= 2; else errs[1]++;
  uint8_t st = 0;
  if (rd(0x1E, 0x09, &st, 1) && (!(st & 1) || rd(0x1E, 0x03, m, 6))) f |= 4; else errs[2]++;
  if ((f & 4) && (st & 1)) f |= 8;
  if ((f ^ ok) & f) init_chips();  // a sensor came back
  ok = f & 7;
  digitalWrite(13, HIGH);
  volatile uint16_t x = 0;
  for (uint16_t i = 0; i < 300; i++) x += i;  // the "update"
  digitalWrite(13, LOW);
  uint8_t b[23];
  put32(b, t); b[4] = f;
  for (uint8_t i = 0; i < 3; i++) {
    put16(b + 5 + 2 * i, (int16_t)(a[2 * i] | a[2 * i + 1] << 8));
    put16(b + 11 + 2 * i, (int16_t)(g[2 * i] << 8 | g[2 * i + 1]));
  }
  put16(b + 17, (int16_t)(m[0] << 8 | m[1])); put16(b + 19, (int16_t)(m[4] << 8 | m[5])); put16(b + 21, (int16_t)(m[2] << 8 | m[3]));
  send(0x02, b, 23);
  if (int1) {
    int1 = false;
    uint8_t src = 0, ts = 0;
    rd(0x53, 0x30, &src, 1); rd(0x53, 0x2B, &ts, 1);
    uint8_t e[8]; put32(e, t);
    e[4] = (src & 0x20) ? 2 : (src & 0x40) ? 1 : (src & 0x04) ? 3 : 0; e[5] = src; e[6] = ts; e[7] = 0;
    if (e[4]) send(0x04, e, 8);
  }
  while (Serial.available()) { Serial.read(); rx_bytes++; }
  if (t - last_status >= 1000000UL) {
    last_status = t;
    uint8_t s[25] = {0};
    put32(s, t); s[4] = ok;
    for (uint8_t i = 0; i < 3; i++) put16(s + 5 + 2 * i, errs[i]);
    put16(s + 17, rx_bytes);
    send(0x05, s, 25);
  }
}
