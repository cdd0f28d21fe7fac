#include "marg_filter.h"

#include "fixed_math.h"
#include "packets.h"

namespace sphere {

void MargFilter::begin(uint16_t dt_us) {
    q_[0] = ONE_Q30;
    q_[1] = q_[2] = q_[3] = 0;
    dt_us_ = dt_us;
    // ½·dt·(π/180/14.375)·2^32 = dt_us · 2.607355 (exact to 1 in 10^6 before rounding)
    gyro_k_ = (int16_t)(2u * dt_us + ((uint32_t)dt_us * 607355ul + 500000ul) / 1000000ul);
    setBetaMilli(DEFAULT_BETA_MILLI);
}

void MargFilter::setBetaMilli(uint16_t beta_milli) {
    beta_milli_ = beta_milli;
    // β·dt·2^23 = beta_milli · dt_us · 2^23 / 10^9
    // = p·256/30517.578 with p = beta_milli·dt_us ≤ 2500·5000 (p·256 < 2^32)
    if (beta_milli > 2500) beta_milli = 2500;
    uint32_t p = (uint32_t)beta_milli * dt_us_;
    beta_dt_ = (int32_t)((p * 256ul + 15259ul) / 30518ul);
}

void MargFilter::setQuaternion(const int32_t q[4]) {
    for (uint8_t i = 0; i < 4; ++i) q_[i] = q[i];
}

void MargFilter::quaternionQ14(int16_t out[4]) const {
    for (uint8_t i = 0; i < 4; ++i) out[i] = (int16_t)((q_[i] + 0x8000l) >> 16);
}

static inline int16_t r14(int32_t q28) { return rshift14(q28); }
static inline int16_t r15(int32_t q28) { return rshift15(q28); }
static inline int16_t r13(int32_t q28) { return rshift13(q28); }
static inline int16_t q14of(int32_t q30) { return hi16(q30 + 0x8000l); }

// ½·dt·(π/180/14.375)·2^32 for dt ≤ 10 ms: dt_us · 2.607355 = dt_us · 170877/2^16
static int16_t gyroK(uint16_t dt_us) { return (int16_t)(((uint32_t)dt_us * 170877ul + 32768ul) >> 16); }

// v (int32) × k/2^16 (k < 2^15) → int32, exact to 1 LSB without a 64-bit product
static inline int32_t scaleQ16(int32_t v, int16_t k) {
    int16_t hi = hi16(v);
    uint16_t lo = (uint16_t)v;
    return mul16(hi, k) + (int32_t)(uint16_t)(((uint32_t)lo * (uint16_t)k) >> 16);
}

// The magnetic part (eq. 76, 77). J_b is linear in b: J_b = bz·J_g + bx·K(q), so
// ½J_gᵀ f_g + ½J_bᵀ f_b = ½J_gᵀ (f_g + bz·f_b) + ½Kᵀ (bx·f_b). This adds bz·f_b to u (which holds f_g)
// and writes v = bx·f_b, all Q13. q, r2 (bottom row of R(q)) and m̂ are Q14.
static __attribute__((noinline)) void magTerms(const int16_t* q, const int16_t* r2, const int16_t* mn, int16_t* u,
                                               int16_t* v) {
    int16_t q0 = q[0], q1 = q[1], q2 = q[2], q3 = q[3];
    int16_t mx = mn[0], my = mn[1], mz = mn[2];
    // rows 0 and 1 of the rotation matrix sensor→earth, Q14
    int16_t r00 = (int16_t)(16384 - r13(mac2(q2, q2, q3, q3))), r01 = r13(mac2(q1, q2, (int16_t)-q0, q3)),
            r02 = r13(mac2(q1, q3, q0, q2));
    int16_t r10 = r13(mac2(q1, q2, q0, q3)), r11 = (int16_t)(16384 - r13(mac2(q1, q1, q3, q3))),
            r12 = r13(mac2(q2, q3, (int16_t)-q0, q1));
    // h = q ⊗ m ⊗ q* and b = [√(hx² + hy²), 0, hz], Q14
    int16_t hx = r14(mac3(r00, mx, r01, my, r02, mz)), hy = r14(mac3(r10, mx, r11, my, r12, mz));
    int16_t bz = r14(mac3(r2[0], mx, r2[1], my, r2[2], mz));
    int16_t bx = (int16_t)sqrtQ28((uint32_t)mac2(hx, hx, hy, hy));
    // magnetic objective f_b = Rᵀ b − m̂ (eq. 76), Q14 → Q13
    int16_t fb[3] = {(int16_t)((r14(mac2(bx, r00, bz, r2[0])) - mx) >> 1),
                     (int16_t)((r14(mac2(bx, r01, bz, r2[1])) - my) >> 1),
                     (int16_t)((r14(mac2(bx, r02, bz, r2[2])) - mz) >> 1)};
    for (uint8_t i = 0; i < 3; ++i) {
        u[i] = (int16_t)(u[i] + r14(mul16(bz, fb[i])));
        v[i] = r14(mul16(bx, fb[i]));
    }
}

// q ← n/‖n‖ for ‖n‖² = 1 + e close to 1: q = n·(1 − e/2 + 3e²/8), with e from the Q14 parts of n.
static __attribute__((noinline)) void renormalise(const int32_t* n, int32_t* q) {
    int16_t h[4];
    for (uint8_t i = 0; i < 4; ++i) h[i] = q14of(n[i]);
    int32_t e28 = mac2(h[0], h[0], h[1], h[1]) + mac2(h[2], h[2], h[3], h[3]) - (1l << 28);
    // Q16; |e| stays below 0.03 (see MARG_FILTER.md), clamped to ±0.25 for safety
    if (e28 > (1l << 26)) e28 = 1l << 26;
    if (e28 < -(1l << 26)) e28 = -(1l << 26);
    int16_t e16 = hi16((int32_t)((uint32_t)(e28 + 2048) << 4));
    int16_t d16 = (int16_t)(-(e16 >> 1) + ((3 * hi16(mul16(e16, e16) + 32768l)) >> 3));
    for (uint8_t i = 0; i < 4; ++i) q[i] = n[i] + mul16(h[i], d16);
}

// The update runs in three out-of-line phases (gyroStep, gradient, renormalise), each with a stack
// frame small enough for the AVR's 6-bit displacement (Y+0 … Y+63): one function holding every
// temporary needed a 128-byte frame, and each access past Y+63 costs a pointer adjustment before and
// after (the split saved 274 bytes of flash and 59 cycles per update). The arithmetic is the same.

// 1. gyro: q ← q + ½ q ⊗ [0, ω]·dt, in Q30, on the Q14 copy of q. Sums in Q14·LSB,
// |sum| ≤ ‖q‖·‖ω‖ < 2^14·1.0001·56756 < 2^30 (q components are within ±16386, so negating them
// cannot overflow; the gyro may be −32768)
static __attribute__((noinline)) void gyroStep(const int16_t* q, const int16_t* g, int16_t k, int32_t* n) {
    int16_t q0 = q[0], q1 = q[1], q2 = q[2], q3 = q[3];
    n[0] += scaleQ16(mac3((int16_t)-q1, g[0], (int16_t)-q2, g[1], (int16_t)-q3, g[2]), k);
    n[1] += scaleQ16(mac3(q0, g[0], q2, g[2], (int16_t)-q3, g[1]), k);
    n[2] += scaleQ16(mac3(q0, g[1], (int16_t)-q1, g[2], q3, g[0]), k);
    n[3] += scaleQ16(mac3(q0, g[2], q1, g[1], (int16_t)-q2, g[0]), k);
}

// 2. the normalised gradient ŝ = ∇f/‖∇f‖ (Q14) of the gravity objective, plus the magnetic one when
// `mn` (the normalised magnetometer, Q14) is given. False when ∇f = 0.
static __attribute__((noinline)) bool gradient(const int16_t* q, const int16_t* an, const int16_t* mn, int16_t* sn) {
    int16_t q0 = q[0], q1 = q[1], q2 = q[2], q3 = q[3];
    // bottom row of the rotation matrix sensor→earth, Q14 (entries within ±1)
    int16_t r2[3] = {r13(mac2(q1, q3, (int16_t)-q0, q2)), r13(mac2(q0, q1, q2, q3)),
                     (int16_t)(16384 - r13(mac2(q1, q1, q2, q2)))};
    // gravity objective (eq. 74), Q13
    int16_t u[3] = {(int16_t)((r2[0] - an[0]) >> 1), (int16_t)((r2[1] - an[1]) >> 1),
                    (int16_t)((r2[2] - an[2]) >> 1)};
    int16_t v[3];
    if (mn) magTerms(q, r2, mn, u, v);
    // ∇f/2 = ½J_gᵀ u (+ ½Kᵀ v), Q26. Half the Jacobians (a common factor does not change
    // ∇f/‖∇f‖): ½J_g = [[−q2, q3, −q0, q1], [q1, q0, q3, q2], [0, −2q1, −2q2, 0]] (eq. 75) and
    // ½K = [[0, 0, −2q2, −2q3], [−q3, q2, q1, −q0], [q2, q3, q0, q1]]; entries Q13 (c_i = q_i,
    // and the Q14 value of q_i read as Q13 is 2q_i).
    int16_t c0 = q0 >> 1, c1 = q1 >> 1, c2 = q2 >> 1, c3 = q3 >> 1;
    int32_t s[4] = {mac2((int16_t)-c2, u[0], c1, u[1]), mac3(c3, u[0], c0, u[1], (int16_t)-q1, u[2]),
                    mac3((int16_t)-c0, u[0], c3, u[1], (int16_t)-q2, u[2]), mac2(c1, u[0], c2, u[1])};
    if (mn) {
        s[0] += mac2((int16_t)-c3, v[1], c2, v[2]);
        s[1] += mac2(c2, v[1], c3, v[2]);
        s[2] += mac3((int16_t)-q2, v[0], c1, v[1], c0, v[2]);
        s[3] += mac3((int16_t)-q3, v[0], (int16_t)-c0, v[1], c1, v[2]);
    }
    return normaliseQ14(s, 4, sn);
}

uint8_t MargFilter::update(const int16_t g[3], const int16_t a[3], const int16_t m[3], bool acc_valid,
                           bool mag_valid, uint16_t dt_us) {
    uint8_t flags = 0;
    // state in Q14 for the products (rounded)
    int16_t q[4] = {q14of(q_[0]), q14of(q_[1]), q14of(q_[2]), q14of(q_[3])};
    int16_t k = (int16_t)gyro_k_;
    if (dt_us && dt_us != dt_us_) {  // after an overrun: the real interval, in steps of ≤ 10 ms
        if (dt_us > MAX_DT_US) dt_us = MAX_DT_US;
        for (; dt_us > 10000; dt_us = (uint16_t)(dt_us - 10000)) gyroStep(q, g, gyroK(10000), q_);
        k = gyroK(dt_us);
    }
    gyroStep(q, g, k, q_);

    int16_t an[3], mn[3], sn[4];
    if (!acc_valid || !normaliseQ14(a, 3, an)) {
        flags |= ORI_ACCEL_REJECTED;
    } else {
        bool marg = mag_valid && normaliseQ14(m, 3, mn);
        if (marg) flags |= ORI_MAG_USED;
        if (gradient(q, an, marg ? mn : 0, sn)) {
            // q̇ −= β ∇f/‖∇f‖ ; step = ŝ(Q14)·β·dt(2^23) → Q30
            // (ŝ·B) >> 7 with B = bh·2^8 + bl, as two 16-bit products (no 32 × 32 multiply)
            int16_t bh = (int16_t)(beta_dt_ >> 8), bl = (int16_t)(beta_dt_ & 0xFF);
            for (uint8_t i = 0; i < 4; ++i)
                q_[i] -= (mul16(sn[i], bh) + ((mul16(sn[i], bl) + 128) >> 8)) << 1;
        }
    }
    renormalise(q_, q_);  // in place: it reads all of n before writing q
    return flags;
}

void MargFilter::rotate(const int16_t g[3], uint32_t dt_us) {
    int16_t q[4] = {q14of(q_[0]), q14of(q_[1]), q14of(q_[2]), q14of(q_[3])};
    for (; dt_us > 10000; dt_us -= 10000) gyroStep(q, g, gyroK(10000), q_);
    gyroStep(q, g, gyroK((uint16_t)dt_us), q_);
    renormalise(q_, q_);
}

void MargFilter::predictQ14(const int16_t g[3], uint16_t ahead_us, int16_t out[4]) const {
    int32_t n[4];
    int16_t q[4];
    for (uint8_t i = 0; i < 4; ++i) {
        n[i] = q_[i];
        q[i] = q14of(q_[i]);
    }
    gyroStep(q, g, gyroK(ahead_us), n);
    renormalise(n, n);
    for (uint8_t i = 0; i < 4; ++i) out[i] = q14of(n[i]);
}

void MargFilter::up(int16_t r2[3]) const {
    int16_t q0 = q14of(q_[0]), q1 = q14of(q_[1]), q2 = q14of(q_[2]), q3 = q14of(q_[3]);
    r2[0] = r13(mac2(q1, q3, (int16_t)-q0, q2));
    r2[1] = r13(mac2(q0, q1, q2, q3));
    r2[2] = (int16_t)(16384 - r13(mac2(q1, q1, q2, q2)));
}


}  // namespace sphere
