#include "adxl345.h"

#include "flash_table.h"

namespace sphere {

const TapSettings Adxl345::DEFAULT_TAP = {48, 32, 80, 240, 7};
const FreeFallSettings Adxl345::DEFAULT_FREE_FALL = {7, 30};

void Adxl345::decode(const uint8_t raw[6], int16_t out[3]) {
    for (uint8_t i = 0; i < 3; ++i) out[i] = (int16_t)(raw[2 * i] | ((uint16_t)raw[2 * i + 1] << 8));
}

// Standby with interrupts off while configuring, then no offsets, the FIFO bypassed (DATAX0.. the newest
// sample; switching to bypass also empties it, "Register 0x38—FIFO_CTL"), format, rate and routing: tap,
// double tap and free fall on INT1 (bit = 0), everything else to the unused INT2.
static const uint8_t ADXL_SETUP[][2] SPHERE_TABLE = {
    {Adxl345::POWER_CTL, 0},
    {Adxl345::INT_ENABLE, 0},
    {Adxl345::OFSX, 0},
    {Adxl345::OFSY, 0},
    {Adxl345::OFSZ, 0},
    {Adxl345::FIFO_CTL, 0},
    {Adxl345::DATA_FORMAT, Adxl345::DATA_FORMAT_FULL_RES_16G},
    {Adxl345::BW_RATE, Adxl345::BW_RATE_400HZ},
    {Adxl345::INT_MAP, (uint8_t)~Adxl345::EVENT_INTS},
};
// after the latched INT_SOURCE was cleared: the event interrupts on, then measurement
static const uint8_t ADXL_START[][2] SPHERE_TABLE = {
    {Adxl345::INT_ENABLE, Adxl345::EVENT_INTS},
    {Adxl345::POWER_CTL, Adxl345::POWER_CTL_MEASURE},
};

bool Adxl345::begin(const TapSettings& tap, const FreeFallSettings& ff) {
    devid_ = 0;
    uint8_t id;
    if (!bus_.readRegister(ADDRESS, DEVID, id)) return false;
    devid_ = id;
    if (id != DEVID_VALUE) return false;
    uint8_t ignored;
    return bus_.writeSequence(ADDRESS, ADXL_SETUP, sizeof ADXL_SETUP / 2) && writeTap(tap) && writeFreeFall(ff) &&
           bus_.readRegister(ADDRESS, INT_SOURCE, ignored) &&  // clear anything latched
           bus_.writeSequence(ADDRESS, ADXL_START, sizeof ADXL_START / 2);
}

// The chip increments the register address within a multi-byte write: DUR, LATENT and WINDOW
// (0x21 … 0x23) in one, THRESH_FF and TIME_FF (0x28, 0x29) in one, from the structs' field order.
bool Adxl345::writeTap(const TapSettings& t) {
    return bus_.writeRegister(ADDRESS, THRESH_TAP, t.thresh_tap) && bus_.writeRegisters(ADDRESS, DUR, &t.dur, 3) &&
           bus_.writeRegister(ADDRESS, TAP_AXES, t.tap_axes);
}

bool Adxl345::writeFreeFall(const FreeFallSettings& f) { return bus_.writeRegisters(ADDRESS, THRESH_FF, &f.thresh_ff, 2); }

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
