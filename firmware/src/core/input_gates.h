// Which accelerometer and magnetometer samples the MARG filter may trust (firmware/MARG_FILTER.md,
// "Input gates"). The accelerometer is used when its norm is near 1 g (a swing or a shake adds to
// gravity); the magnetometer when its norm and its dip (the angle between the field and the
// horizontal plane of the current orientation) are near a reference learned from the accepted samples,
// so a magnet nearby does not drag the heading. Pure logic: the device and the native tests share it.
#pragma once
#include <stdint.h>

namespace sphere {

struct GateSettings {
    uint16_t accel_tol_lsb;    // |‖a‖ − 1 g| allowed, accelerometer LSB (256 per g)
    uint8_t mag_norm_tol_q8;   // |‖m‖ − ref| allowed, as a fraction of ref (1/256)
    uint16_t mag_dip_tol_q14;  // |sin dip − ref| allowed, Q14
    uint8_t learn_shift;       // the reference moves 1/2^shift of the way to each accepted sample
    uint16_t relearn_after;    // this many rejected samples in a row: the reference is learned anew
    uint8_t hold;              // a rejection lasts until this many samples in a row passed again
    static const GateSettings DEFAULTS;
};

class InputGates {
public:
    explicit InputGates(const GateSettings& s = GateSettings::DEFAULTS) : s_(s) { reset(); }
    void setSettings(const GateSettings& s) { s_ = s; }
    const GateSettings& settings() const { return s_; }
    void reset();  // forget the field reference
    // Calibrated accelerometer (256 LSB/g): true when its norm is within the tolerance of 1 g and has
    // been for `hold` samples (a swing's acceleration passes through 1 g without ending).
    bool accel(const int16_t a[3]);
    // Calibrated magnetometer (1090 LSB/gauss) and `up`, the earth's vertical in the sensor frame (Q14,
    // unit length). True when it matches the learned field; learns from it when true. While
    // `learning` (the orientation is not yet trusted) every plausible sample is taken into the
    // reference. An overflowed or implausible reading is always false.
    bool mag(const int16_t m[3], const int16_t up[3], bool learning);
    int16_t refNorm() const { return ref_norm_; }
    int16_t refDip() const { return ref_dip_; }
    bool hasReference() const { return have_ref_; }

private:
    GateSettings s_;
    int16_t ref_norm_, ref_dip_;
    uint16_t rejected_run_;
    uint8_t accel_hold_, mag_hold_;  // samples still to pass before a rejection ends
    bool have_ref_;
};

}  // namespace sphere
