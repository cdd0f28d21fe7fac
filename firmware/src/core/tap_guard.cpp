#include "tap_guard.h"

#include "adxl345.h"

namespace sphere {

void TapGuard::reset() {
    for (uint8_t i = 0; i < 3; ++i) prev_[i] = base_[i] = peak_[i] = 0;
    jump_lsb_ = Adxl345::DEFAULT_TAP.thresh_tap * 8;
    hold_ = 0;
    primed_ = false;
}

bool TapGuard::update(const int16_t a[3]) {
    if (!primed_) {
        for (uint8_t i = 0; i < 3; ++i) prev_[i] = base_[i] = a[i];
        primed_ = true;
        return false;
    }
    bool spike = false;
    for (uint8_t i = 0; i < 3; ++i) {
        int16_t d = (int16_t)(a[i] - prev_[i]);
        if (d > jump_lsb_ || d < -jump_lsb_) spike = true;
    }
    if (spike) {
        if (hold_ == 0) {
            // a new spike: the previous sample is the baseline
            for (uint8_t i = 0; i < 3; ++i) {
                base_[i] = prev_[i];
                peak_[i] = 0;
            }
        }
        hold_ = HOLD_SAMPLES;
    }
    if (hold_ > 0) {
        for (uint8_t i = 0; i < 3; ++i) {
            int16_t dev = (int16_t)(a[i] - base_[i]);
            int16_t ad = dev < 0 ? (int16_t)-dev : dev, ap = peak_[i] < 0 ? (int16_t)-peak_[i] : peak_[i];
            if (ad > ap) peak_[i] = dev;
        }
        if (!spike) --hold_;
    }
    for (uint8_t i = 0; i < 3; ++i) prev_[i] = a[i];
    return hold_ > 0;
}

uint8_t tapEvents(uint32_t t_us, uint8_t int_source, uint8_t act_tap_status, const TapGuard& guard, Event out[2]) {
    uint8_t n = 0;
    uint8_t kind = (int_source & Adxl345::INT_DOUBLE_TAP)   ? EVENT_DOUBLE_TAP
                   : (int_source & Adxl345::INT_SINGLE_TAP) ? EVENT_SINGLE_TAP
                                                            : 0;
    if (kind) {
        int8_t sign = 0;
        // ACT_TAP_STATUS bits 2, 1, 0: tap first seen on x, y, z
        if (act_tap_status & 0x04) sign = guard.sign(0);
        else if (act_tap_status & 0x02) sign = guard.sign(1);
        else if (act_tap_status & 0x01) sign = guard.sign(2);
        out[n++] = Event{t_us, kind, int_source, act_tap_status, sign};
    }
    if (int_source & Adxl345::INT_FREE_FALL) out[n++] = Event{t_us, EVENT_FREE_FALL, int_source, act_tap_status, 0};
    return n;
}

}  // namespace sphere
