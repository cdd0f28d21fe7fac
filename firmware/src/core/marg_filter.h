// Fixed-point Madgwick MARG filter (Madgwick 2010; seed digest §4), the algorithm the host's
// double-precision reference (host/sphere/fusion/madgwick.py) defines. Q formats, ranges and the
// proof sketch that it neither drifts at rest nor overflows at ±2000 °/s: firmware/MARG_FILTER.md.
//
// Inputs are calibrated chip units: gyroscope ITG-3200 LSB (14.375 LSB per °/s), accelerometer and
// magnetometer in any consistent unit (only their directions are used). Earth frame NWU; the state
// is the sensor→earth quaternion w, x, y, z in Q30.
#pragma once
#include <stdint.h>

namespace sphere {

class MargFilter {
public:
    static const uint16_t DEFAULT_DT_US = 5000;      // 200 Hz sample clock
    static const uint16_t DEFAULT_BETA_MILLI = 41;   // Madgwick's published 0.041
    static const uint16_t STARTUP_BETA_MILLI = 1000; // gain while converging after power-up
    static const int32_t ONE_Q30 = 1l << 30;

    explicit MargFilter(uint16_t dt_us = DEFAULT_DT_US) { begin(dt_us); }

    // Identity orientation, the given sample period and the default β.
    void begin(uint16_t dt_us = DEFAULT_DT_US);
    void setBetaMilli(uint16_t beta_milli);  // β in 1/1000 (rad/s), 0 … 2500
    uint16_t betaMilli() const { return beta_milli_; }
    void setQuaternion(const int32_t q_q30[4]);

    // One update. `acc_valid` false or an all-zero accelerometer: gyro only (no gradient step).
    // `mag_valid` false or an all-zero magnetometer: gravity only (IMU step).
    // `dt_us`: the time since the previous update when it was not the sample period (after an
    // overrun; 0 = the period). Up to MAX_DT_US is integrated, in steps of at most 10 ms.
    // Returns ORIENTATION flags: bit 0 mag_used, bit 1 accel_rejected.
    uint8_t update(const int16_t gyro[3], const int16_t accel[3], const int16_t mag[3], bool acc_valid,
                   bool mag_valid, uint16_t dt_us = 0);
    static const uint16_t MAX_DT_US = 50000;
    // Rotates the state by the calibrated rate `gyro` (LSB) held for `dt_us` (in steps of ≤ 10 ms),
    // without a gradient step: the device bridges a gap in the gyroscope's samples with it.
    void rotate(const int16_t gyro[3], uint32_t dt_us);
    // The earth's vertical (NWU z) in the sensor frame: the bottom row of the rotation, Q14.
    void up(int16_t out[3]) const;

    const int32_t* quaternionQ30() const { return q_; }
    void quaternionQ14(int16_t out[4]) const;
    // The orientation `ahead_us` (≤ 10 ms) later at the calibrated rate `gyro` (LSB), Q14: one gyro
    // step from the state, normalised; the state itself is not changed. ORIENTATION packets carry it
    // so that their quaternion is the orientation at their t_us, not the gyroscope's delay before it.
    void predictQ14(const int16_t gyro[3], uint16_t ahead_us, int16_t out[4]) const;


private:
    int32_t q_[4];         // Q30 state
    uint16_t gyro_k_;      // ½·dt·(rad/s per LSB)·2^32: gyro increment scale
    int32_t beta_dt_;      // β·dt·2^23
    uint16_t dt_us_;
    uint16_t beta_milli_;
};

}  // namespace sphere
