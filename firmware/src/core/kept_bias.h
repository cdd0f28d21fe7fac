// The gyro bias kept over a reset that is not a power-on (a watchdog reset, the reset pin pulsed by a host
// opening the port, a brown-out that left the RAM as it was), so that the firmware goes on from the bias it
// had tracked instead of starting from 0 or from the EEPROM's and drifting at the chip's own bias (≈ 1–5 °/s)
// until the next still second. The record lives in RAM that the C start-up does not clear (`.noinit` on the
// AVR, AvrBoard::keptBias()); the ATmega328P's SRAM keeps its contents over every reset but a power-on
// (datasheet, "System Control and Reset"). Whether it is used is decided by the reset cause and by the record
// itself: after a power-on (PORF) the RAM is not defined and the record is ignored whatever it says; after
// any other reset it is used only when its magic, its CRC-16 and its range hold (a brown-out deep enough to
// lose RAM without reaching the power-on threshold, or another image's RAM layout, fails them).
#pragma once
#include <stdint.h>

namespace sphere {

struct __attribute__((packed)) KeptBias {
    uint16_t magic;         // KEPT_BIAS_MAGIC: this layout
    int16_t gyro_bias[3];   // gyroscope LSB, as the calibration holds it
    uint8_t cal_bits;       // calibration_state's CAL_GYRO_BIAS_VALID and CAL_GYRO_BIAS_ESTIMATED
    uint16_t check;         // CRC-16/CCITT-FALSE over the bytes before it
};

const uint16_t KEPT_BIAS_MAGIC = 0xB1A5;
// the largest bias a record may hold: the calibration block's limit (protocol/spec.md §5.2, ±1000 LSB =
// ±70 °/s, beyond the ITG-3200's initial zero-rate tolerance of ±40 °/s, datasheet §3.1)
const int16_t KEPT_BIAS_LIMIT_LSB = 1000;

// Writes the record (magic, values, check word).
void keepBias(KeptBias& k, const int16_t bias[3], uint8_t cal_bits);
// True when the record's magic and check word hold and every axis is within ±KEPT_BIAS_LIMIT_LSB.
bool keptBiasValid(const KeptBias& k);

}  // namespace sphere
