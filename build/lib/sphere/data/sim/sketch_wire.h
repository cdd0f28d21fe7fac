// sketch_wire.h - the burst read the board's own sketches (testfw, probe) share.
// Part of the MARG sphere's virtual board (hardware/sim); GPL-3.0-or-later like the board.
#pragma once
#include <Wire.h>

// Register pointer written without a STOP, then n bytes read: false on a NACK or a short read.
static bool rd(uint8_t a, uint8_t r, uint8_t *b, uint8_t n) {
  Wire.beginTransmission(a); Wire.write(r);
  if (Wire.endTransmission(false) != 0) { Wire.endTransmission(); return false; }
  if (Wire.requestFrom(a, n) != n) return false;
  for (uint8_t i = 0; i < n; i++) b[i] = Wire.read();
  return true;
}
