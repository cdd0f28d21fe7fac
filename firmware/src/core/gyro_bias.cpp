#include "gyro_bias.h"

namespace sphere {

void GyroBiasEstimator::start(uint16_t samples) {
    target_ = samples;
    count_ = 0;
    for (uint8_t i = 0; i < 3; ++i) sum_[i] = mdiff_[i] = 0;
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
    bool second = count_ >= target_ / 2;
    for (uint8_t i = 0; i < 3; ++i) {
        sum_[i] += g[i];
        if (m) mdiff_[i] += second ? -m[i] : m[i];
    }
    if (++count_ < target_) return 0;
    target_ = 0;
    int32_t lim = (int32_t)MAG_DRIFT_LSB * (count_ / 2);
    for (uint8_t i = 0; i < 3; ++i) {
        int32_t s = sum_[i], h = (int32_t)(count_ / 2);
        if (mdiff_[i] > lim || mdiff_[i] < -lim) return -1;  // the field turned: a slow steady turn
        bias_[i] = (int16_t)((s >= 0 ? s + h : s - h) / (int32_t)count_);
    }
    return 1;
}

}  // namespace sphere
