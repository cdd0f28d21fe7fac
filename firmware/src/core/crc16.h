// CRC-16/CCITT-FALSE (poly 0x1021, init 0xFFFF, no reflection, xorout 0): protocol/spec.md §2.
#pragma once
#include <stddef.h>
#include <stdint.h>

namespace sphere {

const uint16_t CRC16_INIT = 0xFFFF;

uint16_t crc16Update(uint16_t crc, uint8_t byte);
uint16_t crc16(const uint8_t* data, size_t len, uint16_t crc = CRC16_INIT);

}  // namespace sphere
