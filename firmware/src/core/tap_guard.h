// Tap handling around the ADXL345's own engines. A tap is an acceleration spike; while one is in
// progress (seen in the samples, or reported by the chip's interrupt) the MARG filter must ignore the
// accelerometer. TapGuard marks that window and remembers the spike's sign per axis for the EVENT's
// tap_sign. TapEvents turns one INT_SOURCE read into EVENT packets.
#pragma once
#include <stdint.h>

#include "packets.h"

namespace sphere {

class TapGuard {
public:
    static const uint8_t HOLD_SAMPLES = 12;  // 60 ms at 200 Hz after the last spike sample

    TapGuard() { reset(); }
    void reset();
    // thresh_tap in the ADXL345's 62.5 mg/LSB (16 accelerometer LSB at 256 LSB/g).
    void setThreshold(uint8_t thresh_tap) { jump_lsb_ = (int16_t)(thresh_tap * 8); }  // half the tap threshold
    // One raw accelerometer sample; returns true while a tap is in progress.
    bool update(const int16_t accel[3]);
    // The chip reported a tap: keep the accelerometer out for another hold window.
    void onTapInterrupt() { hold_ = HOLD_SAMPLES; }
    bool active() const { return hold_ > 0; }
    // +1/−1: sign of the largest deviation on the axis (0 x, 1 y, 2 z) in the last spike; 0 unknown.
    int8_t sign(uint8_t axis) const { return peak_[axis] > 0 ? 1 : peak_[axis] < 0 ? -1 : 0; }

private:
    int16_t prev_[3], base_[3], peak_[3];
    int16_t jump_lsb_;
    uint8_t hold_;
    bool primed_;
};

// EVENT packets from one INT_SOURCE / ACT_TAP_STATUS read: a double tap (DOUBLE_TAP set) is
// reported as double_tap only; SINGLE_TAP alone as single_tap; FREE_FALL as free_fall.
// Returns the number of events written to `out` (at most 2).
uint8_t tapEvents(uint32_t t_us, uint8_t int_source, uint8_t act_tap_status, const TapGuard& guard, Event out[2]);

}  // namespace sphere
