#include "qmc5883l.h"

#include "flash_table.h"

namespace sphere {

static const uint8_t QMC_SETUP[][2] SPHERE_TABLE = {
    {Qmc5883l::SET_RESET, 0x01},
    {Qmc5883l::CONTROL_1, Qmc5883l::CONTROL_1_100HZ_8G},
};

bool Qmc5883l::begin() {
    id_ = 0;
    uint8_t id;
    if (!bus_.readRegister(ADDRESS, CHIP_ID, id)) return false;
    id_ = id;
    if (id != CHIP_ID_VALUE) return false;
    return bus_.writeSequence(ADDRESS, QMC_SETUP, sizeof QMC_SETUP / 2);
}

void Qmc5883l::decode(const uint8_t r[6], int16_t out[3]) {
    for (uint8_t i = 0; i < 3; ++i) {
        int32_t v = (int16_t)(r[2 * i] | ((uint16_t)r[2 * i + 1] << 8));
        out[i] = (int16_t)((v * 23811l + 32768l) >> 16);  // × 1090/3000 (23811/65536 = 0.363327)
    }
}

bool Qmc5883l::poll(int16_t out[3], bool& fresh) {
    fresh = false;
    uint8_t status;
    if (!bus_.readRegister(ADDRESS, STATUS, status)) return false;
    if (!(status & STATUS_DRDY)) return true;
    uint8_t raw[6];
    if (!bus_.readRegisters(ADDRESS, DATA_X_LSB, raw, 6)) return false;
    decode(raw, out);
    if (status & STATUS_OVL) out[0] = out[1] = out[2] = -4096;
    fresh = true;
    return true;
}

}  // namespace sphere
