// Gyroscope bias from a still period: averages `samples` gyroscope readings and accepts the mean
// only when every gyroscope and accelerometer reading stayed within half a few-LSB span of the window's
// first one, and the magnetometer did not turn: the mean of the window's second half is within
// MAG_DRIFT_LSB of the first half's on every axis (and no single reading left a wide span); readings
// without a magnetometer (missing, not yet read) are left out of both means, so a magnetometer glitch
// does not end a still window, and without a reading in either half the field is not judged. The
// magnetometer matters: a steady turn about the vertical keeps the gyro and the accelerometer constant,
// and only the field's direction shows it. Half-window means, not a peak-to-peak span: a module's field
// noise (the BROAD recordings' ≈ ±15 LSB) fails a tight span on every window while a mean sees a turn
// of two degrees per second (the gyroscope's own span) in a 1 s window.
#pragma once
#include <stdint.h>

namespace sphere {

class GyroBiasEstimator {
public:
    // spans wide enough for the chips' noise (ITG-3200 ≈ 0.4 °/s rms, ADXL345 ≈ 4 mg, HMC5883L ≈ 2 mG)
    static const int16_t GYRO_SPAN_LSB = 58;   // ±2 °/s around the first reading
    static const int16_t ACCEL_SPAN_LSB = 24;  // ±47 mg
    static const int16_t MAG_SPAN_LSB = 96;    // ±44 mG per reading: a jolt shows at once
    static const int16_t MAG_DRIFT_LSB = 4;    // half means 4 LSB apart: a turn of ≈ 2 °/s over 1 s (0.2 G horizontal)

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
    int32_t msum_[2][3];  // Σ magnetometer over the first and the second half of the window
    uint16_t mcount_[2];  // readings with a magnetometer in each half
    int16_t g0_[3], a0_[3], m0_[3];  // the window's first sample
    int16_t bias_[3];
};

}  // namespace sphere
