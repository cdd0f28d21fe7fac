// Small fixed-point helpers for the MARG filter (integer only; no division in the hot path).
#pragma once
#include <stdint.h>

namespace sphere {

// Signed 16 × 16 → 32 multiply. On the AVR an inline MUL/MULS/MULSU sequence (Atmel AVR201) of
// 17 cycles: avr-gcc otherwise widens the operands and calls the 32 × 32 routine.
__attribute__((always_inline)) inline int32_t mul16(int16_t a, int16_t b) {
#if defined(__AVR__) && defined(__AVR_HAVE_MUL__)
    int32_t r;
    uint8_t z;
    __asm__(
        "clr %[z]\n\t"
        "muls %B[a], %B[b]\n\t"
        "movw %C[r], r0\n\t"
        "mul %A[a], %A[b]\n\t"
        "movw %A[r], r0\n\t"
        "mulsu %B[a], %A[b]\n\t"
        "sbc %D[r], %[z]\n\t"
        "add %B[r], r0\n\t"
        "adc %C[r], r1\n\t"
        "adc %D[r], %[z]\n\t"
        "mulsu %B[b], %A[a]\n\t"
        "sbc %D[r], %[z]\n\t"
        "add %B[r], r0\n\t"
        "adc %C[r], r1\n\t"
        "adc %D[r], %[z]\n\t"
        "clr r1"
        : [r] "=&r"(r), [z] "=&r"(z)
        : [a] "a"(a), [b] "a"(b));
    return r;
#else
    return (int32_t)a * b;
#endif
}

// Unsigned 16 × 16 → 32 multiply (inline MUL sequence on the AVR).
__attribute__((always_inline)) inline uint32_t umul16(uint16_t a, uint16_t b) {
#if defined(__AVR__) && defined(__AVR_HAVE_MUL__)
    uint32_t r;
    uint8_t z;
    __asm__(
        "clr %[z]\n\t"
        "mul %B[a], %B[b]\n\t"
        "movw %C[r], r0\n\t"
        "mul %A[a], %A[b]\n\t"
        "movw %A[r], r0\n\t"
        "mul %B[a], %A[b]\n\t"
        "add %B[r], r0\n\t"
        "adc %C[r], r1\n\t"
        "adc %D[r], %[z]\n\t"
        "mul %B[b], %A[a]\n\t"
        "add %B[r], r0\n\t"
        "adc %C[r], r1\n\t"
        "adc %D[r], %[z]\n\t"
        "clr r1"
        : [r] "=&r"(r), [z] "=&r"(z)
        : [a] "r"(a), [b] "r"(b));
    return r;
#else
    return (uint32_t)a * b;
#endif
}

inline uint16_t hi16u(uint32_t x) { return (uint16_t)(x >> 16); }

// Sums of two and three 16 × 16 products. Out of line on purpose: the MARG update calls them about
// 40 times, and one copy of the multiply sequence each keeps the filter near 3 KB of flash instead of 7.
int32_t mac2(int16_t a0, int16_t b0, int16_t a1, int16_t b1);
int32_t mac3(int16_t a0, int16_t b0, int16_t a1, int16_t b1, int16_t a2, int16_t b2);

// The upper 16 bits of x (a register move on the AVR, no shift loop).
inline int16_t hi16(int32_t x) { return (int16_t)((uint32_t)x >> 16); }
// Rounded x / 2^13, x / 2^14, x / 2^15 as int16 (result must fit): shifts left by 3, 2, 1 and takes
// the upper word, which avr-gcc does without a 13-step shift loop.
inline int16_t rshift13(int32_t x) { return hi16((int32_t)((uint32_t)(x + 4096) << 3)); }
inline int16_t rshift14(int32_t x) { return hi16((int32_t)((uint32_t)(x + 8192) << 2)); }
inline int16_t rshift15(int32_t x) { return hi16((int32_t)((uint32_t)(x + 16384) << 1)); }

// Scales the `n` (2…4) components of `v` to a unit vector in Q14 (16384 = 1.0).
// Returns false (and writes nothing) when v is all zero. Component error below 1.5e-4.
bool normaliseQ14(const int16_t* v, uint8_t n, int16_t* out);
bool normaliseQ14(const int32_t* v, uint8_t n, int16_t* out);

// √N for N ≤ 2^30 (a Q28 value in, Q14 out), via invSqrtQ14; 0 for 0. Relative error about 5e-5.
uint16_t sqrtQ28(uint32_t n);

// 1/√X for X = x/65536 in [0.25, 1) (x in [16384, 65536)), result in Q14 (16385…32768).
uint16_t invSqrtQ14(uint16_t x_q16);

}  // namespace sphere
