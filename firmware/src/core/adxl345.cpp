#include "adxl345.h"

namespace sphere {

const TapSettings Adxl345::DEFAULT_TAP = {48, 32, 80, 240, 7};
const FreeFallSettings Adxl345::DEFAULT_FREE_FALL = {7, 30};

void Adxl345::decode(const uint8_t raw[6], int16_t out[3]) {
    for (uint8_t i = 0; i < 3; ++i) out[i] = (int16_t)(raw[2 * i] | ((uint16_t)raw[2 * i + 1] << 8));
}

bool Adxl345::begin(const TapSettings& tap, const FreeFallSettings& ff) {
    devid_ = 0;
    uint8_t id;
    if (!bus_.readRegister(ADDRESS, DEVID, id)) return false;
    devid_ = id;
    if (id != DEVID_VALUE) return false;
    uint8_t ignored;
    bool ok = bus_.writeRegister(ADDRESS, POWER_CTL, 0) &&  // standby while configuring
              bus_.writeRegister(ADDRESS, INT_ENABLE, 0) &&
              bus_.writeRegister(ADDRESS, DATA_FORMAT, DATA_FORMAT_FULL_RES_16G) &&
              bus_.writeRegister(ADDRESS, BW_RATE, BW_RATE_200HZ) && writeTap(tap) && writeFreeFall(ff) &&
              // tap, double tap and free fall on INT1 (bit = 0); everything else to the unused INT2
              bus_.writeRegister(ADDRESS, INT_MAP, (uint8_t)~EVENT_INTS) &&
              bus_.readRegister(ADDRESS, INT_SOURCE, ignored) &&  // clear anything latched
              bus_.writeRegister(ADDRESS, INT_ENABLE, EVENT_INTS) &&
              bus_.writeRegister(ADDRESS, POWER_CTL, POWER_CTL_MEASURE);
    return ok;
}

bool Adxl345::writeTap(const TapSettings& t) {
    return bus_.writeRegister(ADDRESS, THRESH_TAP, t.thresh_tap) && bus_.writeRegister(ADDRESS, DUR, t.dur) &&
           bus_.writeRegister(ADDRESS, LATENT, t.latent) && bus_.writeRegister(ADDRESS, WINDOW, t.window) &&
           bus_.writeRegister(ADDRESS, TAP_AXES, t.tap_axes);
}

bool Adxl345::writeFreeFall(const FreeFallSettings& f) {
    return bus_.writeRegister(ADDRESS, THRESH_FF, f.thresh_ff) && bus_.writeRegister(ADDRESS, TIME_FF, f.time_ff);
}

bool Adxl345::readAccel(int16_t out[3]) {
    uint8_t raw[6];
    if (!bus_.readRegisters(ADDRESS, DATAX0, raw, 6)) return false;
    decode(raw, out);
    return true;
}

bool Adxl345::readEvent(uint8_t& int_source, uint8_t& act_tap_status) {
    return bus_.readRegister(ADDRESS, ACT_TAP_STATUS, act_tap_status) &&
           bus_.readRegister(ADDRESS, INT_SOURCE, int_source);
}

}  // namespace sphere
