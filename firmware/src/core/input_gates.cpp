#include "input_gates.h"

#include "fixed_math.h"

namespace sphere {

// Chosen by leave-one-trial-out over the shipped BROAD trials (firmware/MARG_FILTER.md, "Input gates").
const GateSettings GateSettings::DEFAULTS = {26, 51, 3277, 9, 2000, 0};

void InputGates::reset() {
    ref_norm_ = ref_dip_ = 0;
    rejected_run_ = 0;
    accel_hold_ = mag_hold_ = 0;
    have_ref_ = false;
}

// A sample out of band starts a hold of s_.hold samples; one in band ends a hold only when it has run out.
static bool held(bool in_band, uint8_t& left, uint8_t hold) {
    if (!in_band) {
        left = hold;
        return false;
    }
    if (left) {
        --left;
        return false;
    }
    return true;
}

static uint16_t norm3(const int16_t v[3], bool& ok) {
    int32_t n2 = mac3(v[0], v[0], v[1], v[1], v[2], v[2]);
    ok = n2 > 0 && n2 <= (1l << 30);
    return ok ? sqrtQ28((uint32_t)n2) : 0;
}

bool InputGates::accel(const int16_t a[3]) {
    bool ok;
    int16_t d = (int16_t)(norm3(a, ok) - 256);
    return held(ok && d <= (int16_t)s_.accel_tol_lsb && d >= -(int16_t)s_.accel_tol_lsb, accel_hold_, s_.hold);
}

bool InputGates::mag(const int16_t m[3], const int16_t up[3], bool learning) {
    bool ok;
    uint16_t n = norm3(m, ok);
    // 0.15 … 0.90 gauss: the earth's field is 0.25 … 0.65 gauss anywhere
    if (!ok || n < 164 || n > 981) return false;
    int16_t dip = (int16_t)(mac3(m[0], up[0], m[1], up[1], m[2], up[2]) / (int32_t)n);  // sin(dip), Q14
    if (!have_ref_) {
        ref_norm_ = (int16_t)n;
        ref_dip_ = dip;
        have_ref_ = true;
        rejected_run_ = 0;
        return true;
    }
    int16_t dn = (int16_t)((int16_t)n - ref_norm_), dd = (int16_t)(dip - ref_dip_);
    int16_t norm_tol = (int16_t)(((uint16_t)ref_norm_ * s_.mag_norm_tol_q8) >> 8);
    bool accept = learning || held(dn <= norm_tol && dn >= -norm_tol && dd <= (int16_t)s_.mag_dip_tol_q14 &&
                                       dd >= -(int16_t)s_.mag_dip_tol_q14,
                                   mag_hold_, s_.hold);
    if (!accept) {
        if (++rejected_run_ >= s_.relearn_after) have_ref_ = false;  // somewhere else now: learn again
        return false;
    }
    rejected_run_ = 0;
    uint8_t k = learning ? 3 : s_.learn_shift;
    int16_t half = (int16_t)(1 << (k - 1));  // rounded, so ±1 differences do not walk the reference
    ref_norm_ = (int16_t)(ref_norm_ + ((dn + half) >> k));
    ref_dip_ = (int16_t)(ref_dip_ + ((dd + half) >> k));
    return true;
}

}  // namespace sphere
