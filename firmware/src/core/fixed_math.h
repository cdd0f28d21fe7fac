// Small fixed-point helpers for the MARG filter (integer only; no division in the hot path).
#pragma once
#include <stdint.h>

namespace sphere {

inline int32_t mul16(int16_t a, int16_t b) { return (int32_t)a * b; }

// Scales the `n` (2…4) int32 components of `v` to a unit vector in Q14 (16384 = 1.0).
// Returns false (and writes nothing) when v is all zero. Relative error about 1e-4.
bool normaliseQ14(const int32_t* v, uint8_t n, int16_t* out);

// 1/√X for X = x/65536 in [0.25, 1) (x in [16384, 65536)), result in Q14 (16385…32768).
uint16_t invSqrtQ14(uint16_t x_q16);

}  // namespace sphere
