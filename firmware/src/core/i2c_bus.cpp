#include "i2c_bus.h"

#include "flash_table.h"

namespace sphere {

bool I2cBus::writeSequence(uint8_t addr, const uint8_t (*pairs)[2], uint8_t count) {
    for (uint8_t i = 0; i < count; ++i)
        if (!writeRegister(addr, SPHERE_READ_U8(&pairs[i][0]), SPHERE_READ_U8(&pairs[i][1]))) return false;
    return true;
}

}  // namespace sphere
