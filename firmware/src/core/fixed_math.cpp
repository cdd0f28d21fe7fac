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

// 1/√X at the middle of each of the 192 steps of 1/256 covering [0.25, 1), Q14 (seed within 0.4 %).
static const uint16_t INV_SQRT_SEED[192] SPHERE_TABLE = {
    32641, 32391, 32146, 31907, 31673, 31445, 31221, 31002, 30787, 30577, 30371, 30169,
    29972, 29778, 29587, 29401, 29217, 29038, 28861, 28688, 28518, 28350, 28186, 28024,
    27866, 27709, 27556, 27405, 27256, 27110, 26966, 26825, 26686, 26548, 26413, 26280,
    26149, 26020, 25893, 25767, 25644, 25522, 25402, 25283, 25167, 25051, 24938, 24826,
    24715, 24606, 24498, 24392, 24287, 24184, 24081, 23980, 23881, 23782, 23685, 23589,
    23494, 23400, 23307, 23216, 23125, 23036, 22947, 22860, 22774, 22688, 22604, 22520,
    22437, 22356, 22275, 22195, 22116, 22037, 21960, 21883, 21808, 21732, 21658, 21585,
    21512, 21440, 21368, 21298, 21228, 21159, 21090, 21022, 20955, 20888, 20822, 20757,
    20692, 20628, 20564, 20501, 20439, 20377, 20316, 20255, 20195, 20135, 20076, 20017,
    19959, 19902, 19845, 19788, 19732, 19676, 19621, 19566, 19512, 19458, 19405, 19352,
    19299, 19247, 19196, 19144, 19093, 19043, 18993, 18943, 18894, 18845, 18797, 18749,
    18701, 18653, 18606, 18560, 18513, 18467, 18422, 18376, 18331, 18287, 18242, 18198,
    18155, 18111, 18068, 18025, 17983, 17941, 17899, 17857, 17816, 17775, 17734, 17694,
    17654, 17614, 17574, 17535, 17496, 17457, 17418, 17380, 17342, 17304, 17267, 17229,
    17192, 17155, 17119, 17082, 17046, 17010, 16974, 16939, 16904, 16869, 16834, 16799,
    16765, 16731, 16697, 16663, 16629, 16596, 16563, 16530, 16497, 16465, 16432, 16400};

__attribute__((noinline)) int32_t mac2(int16_t a0, int16_t b0, int16_t a1, int16_t b1) {
    return mul16(a0, b0) + mul16(a1, b1);
}

__attribute__((noinline)) int32_t mac3(int16_t a0, int16_t b0, int16_t a1, int16_t b1, int16_t a2, int16_t b2) {
    return mul16(a0, b0) + mul16(a1, b1) + mul16(a2, b2);
}

uint16_t invSqrtQ14(uint16_t x) {
    // seed within 0.4 %, then one Newton step y ← y(3 − X·y²)/2: error about 2e-5
    uint16_t y = SPHERE_READ_U16(&INV_SQRT_SEED[(uint8_t)((x >> 8) - 64)]);
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
    uint32_t N = (uint32_t)(mul16(w0, w0) + mul16(w1, w1)) + (uint32_t)(mul16(w2, w2) + mul16(w3, w3));
    // x = N·4^k in [2^28, 2^30); X = x/2^30 in [0.25, 1); 1/√N = (1/√X)·2^k/2^15
    bool k = N < (1ul << 28);
    if (k) N <<= 2;
    uint16_t xq = N >= (1ul << 30) ? 0xFFFFu : hi16u(N << 2);
    uint16_t yu = invSqrtQ14(xq);
    int16_t y = (int16_t)(yu > 32767u ? 32767u : yu);  // Q14 (≤ 2.0), as a signed operand
    if (k) {
        out[0] = rshift14(mul16(w0, y));
        out[1] = rshift14(mul16(w1, y));
        if (n > 2) out[2] = rshift14(mul16(w2, y));
        if (n > 3) out[3] = rshift14(mul16(w3, y));
    } else {
        out[0] = rshift15(mul16(w0, y));
        out[1] = rshift15(mul16(w1, y));
        if (n > 2) out[2] = rshift15(mul16(w2, y));
        if (n > 3) out[3] = rshift15(mul16(w3, y));
    }
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
