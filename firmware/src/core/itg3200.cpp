#include "itg3200.h"

#include "flash_table.h"

namespace sphere {

void Itg3200::decode(const uint8_t raw[6], int16_t out[3]) {
    for (uint8_t i = 0; i < 3; ++i) out[i] = (int16_t)(((uint16_t)raw[2 * i] << 8) | raw[2 * i + 1]);
}

// clock from the X gyro's PLL, every sample of the 1 kHz internal rate, ±2000 °/s with the 98 Hz low-pass,
// no interrupt pin
static const uint8_t ITG_SETUP[][2] SPHERE_TABLE = {
    {Itg3200::PWR_MGM, Itg3200::PWR_MGM_PLL_X},
    {Itg3200::SMPLRT_DIV, Itg3200::SMPLRT_DIV_1KHZ},
    {Itg3200::DLPF_FS, Itg3200::DLPF_FS_2000DPS_98HZ},
    {Itg3200::INT_CFG, 0},
};

bool Itg3200::begin() {
    whoami_ = 0;
    const uint8_t candidates[2] = {ADDRESS_AD0_LOW, ADDRESS_AD0_HIGH};
    for (uint8_t i = 0; i < 2; ++i) {
        uint8_t id;
        if (!bus_.readRegister(candidates[i], WHO_AM_I, id)) continue;
        whoami_ = id;
        if (!whoamiValid(id)) continue;
        address_ = candidates[i];
        return bus_.writeSequence(address_, ITG_SETUP, sizeof ITG_SETUP / 2);
    }
    return false;
}

bool Itg3200::readGyro(int16_t out[3]) {
    uint8_t raw[6];
    if (!bus_.readRegisters(address_, GYRO_XOUT_H, raw, 6)) return false;
    decode(raw, out);
    return true;
}

}  // namespace sphere
