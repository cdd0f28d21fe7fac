#include "gyro_bias.h"

namespace sphere {

void GyroBiasEstimator::start(uint16_t samples) {
    target_ = samples;
    count_ = 0;
    for (uint8_t i = 0; i < 3; ++i) sum_[i] = msum_[0][i] = msum_[1][i] = 0;
    mcount_[0] = mcount_[1] = 0;
}

// Still = every reading within ±span/2 of the window's first one, per axis.
static bool near(const int16_t* v, const int16_t* ref, int16_t half_span) {
    for (uint8_t i = 0; i < 3; ++i) {
        int16_t d = (int16_t)(v[i] - ref[i]);
        if (d > half_span || d < -half_span) return false;
    }
    return true;
}

int8_t GyroBiasEstimator::update(const int16_t g[3], const int16_t a[3], const int16_t* m) {
    if (!target_) return 0;
    if (count_ == 0) {
        for (uint8_t i = 0; i < 3; ++i) {
            g0_[i] = g[i];
            a0_[i] = a[i];
            m0_[i] = m ? m[i] : 0;
        }
    }
    if (!near(g, g0_, GYRO_SPAN_LSB / 2) || !near(a, a0_, ACCEL_SPAN_LSB / 2) || (m && !near(m, m0_, MAG_SPAN_LSB / 2))) {
        target_ = 0;
        return -1;
    }
    uint8_t half = count_ >= target_ / 2;
    if (m) ++mcount_[half];
    for (uint8_t i = 0; i < 3; ++i) {
        sum_[i] += g[i];
        if (m) msum_[half][i] += m[i];
    }
    if (++count_ < target_) return 0;
    target_ = 0;
    // mean₁ − mean₂ within ±MAG_DRIFT_LSB, multiplied out: |Σ₁·n₂ − Σ₂·n₁| ≤ MAG_DRIFT_LSB·n₁·n₂
    // (|Σ| ≤ 200·2^15 and n ≤ 200 per half for the windows used: within int32)
    int32_t n1 = mcount_[0], n2 = mcount_[1], lim = (int32_t)MAG_DRIFT_LSB * n1 * n2;
    for (uint8_t i = 0; i < 3; ++i) {
        int32_t s = sum_[i], h = (int32_t)(count_ / 2), d = msum_[0][i] * n2 - msum_[1][i] * n1;
        if (d > lim || d < -lim) return -1;  // the field turned: a slow steady turn
        bias_[i] = (int16_t)((s >= 0 ? s + h : s - h) / (int32_t)count_);
    }
    return 1;
}

}  // namespace sphere
