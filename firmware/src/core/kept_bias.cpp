#include "kept_bias.h"

#include <stddef.h>

#include "crc16.h"

namespace sphere {

static uint16_t keptCheck(const KeptBias& k) { return crc16((const uint8_t*)&k, offsetof(KeptBias, check)); }

void keepBias(KeptBias& k, const int16_t bias[3], uint8_t cal_bits) {
    k.magic = KEPT_BIAS_MAGIC;
    for (uint8_t i = 0; i < 3; ++i) k.gyro_bias[i] = bias[i];
    k.cal_bits = cal_bits;
    k.check = keptCheck(k);
}

bool keptBiasValid(const KeptBias& k) {
    if (k.magic != KEPT_BIAS_MAGIC || k.check != keptCheck(k)) return false;
    for (uint8_t i = 0; i < 3; ++i)
        if (k.gyro_bias[i] > KEPT_BIAS_LIMIT_LSB || k.gyro_bias[i] < -KEPT_BIAS_LIMIT_LSB) return false;
    return true;
}

}  // namespace sphere
