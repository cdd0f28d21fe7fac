#include "fixed_math.h"

#include "flash_table.h"

namespace sphere {

// 1/√X at the middle of each of the 96 steps of 1/128 covering [0.25, 1), Q14 (seed within 0.8 %).
static const uint16_t INV_SQRT_SEED[96] SPHERE_TABLE = {
    32515, 32026, 31558, 31111, 30682, 30270, 29874, 29494, 29127, 28774, 28434, 28105,
    27787, 27480, 27183, 26895, 26617, 26346, 26084, 25830, 25583, 25342, 25109, 24882,
    24660, 24445, 24235, 24031, 23831, 23637, 23447, 23262, 23080, 22904, 22731, 22562,
    22396, 22235, 22077, 21922, 21770, 21621, 21476, 21333, 21193, 21056, 20921, 20789,
    20660, 20533, 20408, 20285, 20165, 20047, 19930, 19816, 19704, 19594, 19485, 19378,
    19273, 19170, 19068, 18968, 18870, 18773, 18677, 18583, 18490, 18399, 18309, 18220,
    18133, 18047, 17962, 17878, 17795, 17714, 17634, 17554, 17476, 17399, 17323, 17248,
    17174, 17100, 17028, 16957, 16886, 16817, 16748, 16680, 16613, 16546, 16481, 16416};

__attribute__((noinline)) int32_t mac2(int16_t a0, int16_t b0, int16_t a1, int16_t b1) {
    return mul16(a0, b0) + mul16(a1, b1);
}

__attribute__((noinline)) int32_t mac3(int16_t a0, int16_t b0, int16_t a1, int16_t b1, int16_t a2, int16_t b2) {
    return mul16(a0, b0) + mul16(a1, b1) + mul16(a2, b2);
}

uint16_t invSqrtQ14(uint16_t x) {
    // seed within 0.8 %, then one Newton step y ← y(3 − X·y²)/2: error below 1e-4
    uint16_t y = SPHERE_READ_U16(&INV_SQRT_SEED[(uint8_t)((x >> 9) - 32)]);
    uint16_t y2 = hi16u(umul16(y, y) << 2);  // y², Q14 (y < 2 here, so no overflow)
    uint16_t t = hi16u(umul16(x, y2));       // X·y², Q14, ≈ 16384
    uint32_t r = umul16(y, (uint16_t)(49152u - t)) + 16384u;
    r = (uint32_t)hi16u(r << 1);
    return r > 32768u ? 32768u : (uint16_t)r;
}

uint16_t sqrtQ28(uint32_t n) {
    if (n == 0) return 0;
    if (n >= (1ul << 30)) n = (1ul << 30) - 1;
    uint8_t k = 0;  // x = n·4^k in [2^28, 2^30)
    while (n < (1ul << 28)) {
        n <<= 2;
        ++k;
    }
    uint16_t xq = hi16u(n << 2);  // X = x/2^30 in Q16
    // √n = 2^15·X·(1/√X) / 2^k
    uint32_t r = umul16(xq, invSqrtQ14(xq));
    r = (uint32_t)hi16u(r << 1);  // >> 15
    return (uint16_t)(r >> k);
}

static inline uint16_t absU16(int16_t x) { return x < 0 ? (uint16_t)-x : (uint16_t)x; }

bool normaliseQ14(const int16_t* v, uint8_t n, int16_t* out) {
    // straight-line for up to four components (a missing fourth is 0): no arrays, no shift loops
    // per component
    int16_t w0 = v[0], w1 = v[1], w2 = n > 2 ? v[2] : 0, w3 = n > 3 ? v[3] : 0;
    uint16_t m = absU16(w0);
    uint16_t t = absU16(w1);
    if (t > m) m = t;
    t = absU16(w2);
    if (t > m) m = t;
    t = absU16(w3);
    if (t > m) m = t;
    if (m == 0) return false;
    // block floating point: the largest component into [2^13, 2^14]
    while (m < (1u << 13)) {
        m <<= 1;
        w0 = (int16_t)((uint16_t)w0 << 1);
        w1 = (int16_t)((uint16_t)w1 << 1);
        w2 = (int16_t)((uint16_t)w2 << 1);
        w3 = (int16_t)((uint16_t)w3 << 1);
    }
    while (m > (1u << 14)) {
        m >>= 1;
        w0 >>= 1;
        w1 >>= 1;
        w2 >>= 1;
        w3 >>= 1;
    }
    uint32_t N = (uint32_t)mac2(w0, w0, w1, w1) + (uint32_t)mac2(w2, w2, w3, w3);
    // x = N·4^k in [2^28, 2^30); X = x/2^30 in [0.25, 1); 1/√N = (1/√X)·2^k/2^15. For k = 1 the
    // components are doubled instead (N < 2^28 means every |w| < 2^14, so 2w fits): N·4 is then their
    // sum of squares and round(2w·y/2^15) = round(w·y/2^14), so one output path serves both.
    if (N < (1ul << 28)) {
        N <<= 2;
        w0 = (int16_t)(w0 * 2);
        w1 = (int16_t)(w1 * 2);
        w2 = (int16_t)(w2 * 2);
        w3 = (int16_t)(w3 * 2);
    }
    uint16_t xq = N >= (1ul << 30) ? 0xFFFFu : hi16u(N << 2);
    uint16_t yu = invSqrtQ14(xq);
    int16_t y = (int16_t)(yu > 32767u ? 32767u : yu);  // Q14 (≤ 2.0), as a signed operand
    out[0] = rshift15(mul16(w0, y));
    out[1] = rshift15(mul16(w1, y));
    if (n > 2) out[2] = rshift15(mul16(w2, y));
    if (n > 3) out[3] = rshift15(mul16(w3, y));
    return true;
}

bool normaliseQ14(const int32_t* v, uint8_t n, int16_t* out) {
    // reduce to 16 bits on a shared exponent, then as int16
    uint32_t m = 0;
    for (uint8_t i = 0; i < n; ++i) {
        uint32_t a = v[i] < 0 ? (uint32_t)(-v[i]) : (uint32_t)v[i];
        if (a > m) m = a;
    }
    int16_t w[4];
    if (m < (1ul << 15)) {
        for (uint8_t i = 0; i < n; ++i) w[i] = (int16_t)v[i];
        return normaliseQ14(w, n, out);
    }
    uint8_t sh = 0;  // smallest shift that brings m below 2^15
    if (m >= (1ul << 23)) {
        m >>= 8;
        sh = 8;
    }
    while (m >= (1ul << 15)) {
        m >>= 1;
        ++sh;
    }
    if (sh == 1) {
        for (uint8_t i = 0; i < n; ++i) w[i] = (int16_t)(v[i] >> 1);
    } else {
        // v >> sh = floor(v·p / 2^16) with p = 2^(16 − sh) ≤ 2^14: two 16-bit multiplies, no shift loop
        int16_t p = (int16_t)(1u << (16 - sh));
        for (uint8_t i = 0; i < n; ++i)
            w[i] = (int16_t)(mul16(hi16(v[i]), p) + (int32_t)hi16u(umul16((uint16_t)v[i], (uint16_t)p)));
    }
    return normaliseQ14(w, n, out);
}

}  // namespace sphere
