#include "hmc5883l.h"

#include "flash_table.h"

namespace sphere {

void Hmc5883l::decode(const uint8_t r[6], int16_t out[3]) {
    out[0] = (int16_t)(((uint16_t)r[0] << 8) | r[1]);  // X
    out[2] = (int16_t)(((uint16_t)r[2] << 8) | r[3]);  // Z
    out[1] = (int16_t)(((uint16_t)r[4] << 8) | r[5]);  // Y
}

// one sample per measurement, ±1.3 Ga (1090 LSB/gauss), then the first single measurement
static const uint8_t HMC_SETUP[][2] SPHERE_TABLE = {
    {Hmc5883l::CONFIG_A, Hmc5883l::CONFIG_A_75HZ},
    {Hmc5883l::CONFIG_B, Hmc5883l::CONFIG_B_GAIN1},
    {Hmc5883l::MODE, Hmc5883l::MODE_SINGLE},
};

bool Hmc5883l::begin() {
    id_[0] = id_[1] = id_[2] = 0;
    if (!bus_.readRegisters(ADDRESS, ID_A, id_, 3)) {
        id_[0] = id_[1] = id_[2] = 0;
        return false;
    }
    if (!idValid(id_)) return false;
    since_trigger_ = 0;
    return bus_.writeSequence(ADDRESS, HMC_SETUP, sizeof HMC_SETUP / 2);
}

bool Hmc5883l::poll(int16_t out[3], bool& fresh) {
    fresh = false;
    if (since_trigger_ < 255) ++since_trigger_;
    if (since_trigger_ < TRIGGER_TICKS) return true;  // converting
    uint8_t status;
    if (!bus_.readRegister(ADDRESS, STATUS, status)) return false;
    if (status & STATUS_RDY) {
        uint8_t raw[6];
        if (!bus_.readRegisters(ADDRESS, DATA_X_MSB, raw, 6)) return false;
        decode(raw, out);
        fresh = true;
    } else if (since_trigger_ < TIMEOUT_TICKS) {
        return true;  // not ready yet
    }
    if (!bus_.writeRegister(ADDRESS, MODE, MODE_SINGLE)) return false;
    since_trigger_ = 0;
    return true;
}

}  // namespace sphere
