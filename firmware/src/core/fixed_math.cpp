#include "fixed_math.h"

#ifdef __AVR__
#include <avr/pgmspace.h>
#define SPHERE_TABLE PROGMEM
#define SPHERE_READ_U16(p) pgm_read_word(p)
#else
#define SPHERE_TABLE
#define SPHERE_READ_U16(p) (*(p))
#endif

namespace sphere {

// 1/√X at the middle of each of 24 intervals of width 1/32 covering [0.25, 1), Q14.
static const uint16_t INV_SQRT_SEED[24] SPHERE_TABLE = {
    31790, 30070, 28602, 27330, 26214, 25225, 24339, 23541, 22817, 22155, 21548, 20988, 20470, 19988, 19539, 19119, 18725, 18354, 18004, 17674, 17361, 17064, 16782, 16514};

uint16_t invSqrtQ14(uint16_t x) {
    // seed within 1.6 %, then two Newton steps y ← y(3 − X·y²)/2: error below 1e-5 before rounding
    uint16_t y = SPHERE_READ_U16(&INV_SQRT_SEED[(uint16_t)(x - 16384u) >> 11]);
    for (uint8_t it = 0; it < 2; ++it) {
        uint32_t y2 = ((uint32_t)y * y) >> 14;                    // Q14, ≤ 65536
        if (y2 > 65535u) y2 = 65535u;
        uint16_t t = (uint16_t)(((uint32_t)x * (uint16_t)y2) >> 16);  // X·y², Q14, ≈ 16384
        uint32_t r = ((uint32_t)y * (uint16_t)(49152u - t) + 16384u) >> 15;
        y = r > 32768u ? 32768u : (uint16_t)r;
    }
    return y;
}

bool normaliseQ14(const int32_t* v, uint8_t n, int16_t* out) {
    uint32_t m = 0;
    for (uint8_t i = 0; i < n; ++i) {
        uint32_t a = v[i] < 0 ? (uint32_t)(-v[i]) : (uint32_t)v[i];
        if (a > m) m = a;
    }
    if (m == 0) return false;
    // block floating point: bring the largest component into [2^13, 2^14)
    int8_t sh = 0;
    while (m >= (1ul << 14)) { m >>= 1; ++sh; }
    while (m < (1ul << 13)) { m <<= 1; --sh; }
    int16_t w[4];
    for (uint8_t i = 0; i < n; ++i) {
        int32_t x = v[i];
        if (sh > 0) x = (x + (1l << (sh - 1))) >> sh;
        else if (sh < 0) x = x << (-sh);
        w[i] = (int16_t)x;
    }
    uint32_t N = 0;  // in [2^26, 2^30]
    for (uint8_t i = 0; i < n; ++i) N += (uint32_t)mul16(w[i], w[i]);
    // x = N·4^k in [2^28, 2^30); X = x/2^30 in [0.25, 1); 1/√N = (1/√X)·2^k/2^15
    uint8_t k = 0;
    if (N < (1ul << 28)) { N <<= 2; k = 1; }
    if (N >= (1ul << 30)) N = (1ul << 30) - 1;
    uint16_t y = invSqrtQ14((uint16_t)(N >> 14));
    uint8_t s = (uint8_t)(15 - k);
    for (uint8_t i = 0; i < n; ++i) {
        int32_t p = (int32_t)w[i] * (int32_t)y;  // |p| < 2^29
        out[i] = (int16_t)((p + (1l << (s - 1))) >> s);
    }
    return true;
}

}  // namespace sphere
