#include "gyro_bias.h"

namespace sphere {

void GyroBiasEstimator::start(uint16_t samples) {
    target_ = samples;
    count_ = 0;
    mag_started_ = false;
    for (uint8_t i = 0; i < 3; ++i) sum_[i] = 0;
}

static bool widen(int16_t v, int16_t& lo, int16_t& hi, int16_t span) {
    if (v < lo) lo = v;
    if (v > hi) hi = v;
    return (int32_t)hi - lo <= span;
}

int8_t GyroBiasEstimator::update(const int16_t g[3], const int16_t a[3], const int16_t* m) {
    if (!target_) return 0;
    if (m) {
        for (uint8_t i = 0; i < 3; ++i) {
            if (!mag_started_) mmin_[i] = mmax_[i] = m[i];
            if (!widen(m[i], mmin_[i], mmax_[i], MAG_SPAN_LSB)) {
                target_ = 0;
                return -1;
            }
        }
        mag_started_ = true;
    }
    for (uint8_t i = 0; i < 3; ++i) {
        if (count_ == 0) {
            gmin_[i] = gmax_[i] = g[i];
            amin_[i] = amax_[i] = a[i];
        }
        if (g[i] < gmin_[i]) gmin_[i] = g[i];
        if (g[i] > gmax_[i]) gmax_[i] = g[i];
        if (a[i] < amin_[i]) amin_[i] = a[i];
        if (a[i] > amax_[i]) amax_[i] = a[i];
        sum_[i] += g[i];
        if ((int32_t)gmax_[i] - gmin_[i] > GYRO_SPAN_LSB || (int32_t)amax_[i] - amin_[i] > ACCEL_SPAN_LSB) {
            target_ = 0;
            return -1;
        }
    }
    if (++count_ < target_) return 0;
    for (uint8_t i = 0; i < 3; ++i) {
        int32_t s = sum_[i], h = (int32_t)(count_ / 2);
        bias_[i] = (int16_t)((s >= 0 ? s + h : s - h) / (int32_t)count_);
    }
    target_ = 0;
    return 1;
}

}  // namespace sphere
