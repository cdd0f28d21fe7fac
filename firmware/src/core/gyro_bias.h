// Gyroscope bias from a still period: averages `samples` gyroscope readings and accepts the mean
// only when neither the gyroscope, the accelerometer nor (when present) the magnetometer moved more
// than a few LSB meanwhile. The magnetometer matters: a steady turn about the vertical keeps the gyro
// and the accelerometer constant, and only the field's direction shows it.
#pragma once
#include <stdint.h>

namespace sphere {

class GyroBiasEstimator {
public:
    static const int16_t GYRO_SPAN_LSB = 15;   // ≈ 1 °/s peak to peak
    static const int16_t ACCEL_SPAN_LSB = 16;  // ≈ 62 mg peak to peak
    static const int16_t MAG_SPAN_LSB = 12;    // ≈ 11 mG peak to peak (≈ 1.3° of heading)

    GyroBiasEstimator() : target_(0), count_(0) {}
    void start(uint16_t samples);
    void stop() { target_ = 0; }
    bool running() const { return target_ != 0; }
    // Feeds one sample. Returns 1 when a still estimate is ready (bias()), −1 when the window
    // was not still (the estimator stops), 0 while collecting.
    // `mag` may be null (no magnetometer).
    int8_t update(const int16_t gyro[3], const int16_t accel[3], const int16_t* mag);
    const int16_t* bias() const { return bias_; }

private:
    uint16_t target_, count_;
    int32_t sum_[3];
    int16_t gmin_[3], gmax_[3], amin_[3], amax_[3], mmin_[3], mmax_[3];
    bool mag_started_;
    int16_t bias_[3];
};

}  // namespace sphere
