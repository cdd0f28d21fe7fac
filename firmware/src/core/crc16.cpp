#include "crc16.h"

namespace sphere {

// Bytewise without a table (no 512-byte table in flash; a frame is at most 64 bytes).
uint16_t crc16Update(uint16_t crc, uint8_t byte) {
    crc ^= (uint16_t)byte << 8;
    for (uint8_t i = 0; i < 8; ++i) crc = (crc & 0x8000) ? (uint16_t)((crc << 1) ^ 0x1021) : (uint16_t)(crc << 1);
    return crc;
}

uint16_t crc16(const uint8_t* data, size_t len, uint16_t crc) {
    for (size_t i = 0; i < len; ++i) crc = crc16Update(crc, data[i]);
    return crc;
}

}  // namespace sphere
