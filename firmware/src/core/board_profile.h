// Board profiles: how each chip is mounted on the sensor board, as a signed permutation per chip
// (protocol/spec.md §4.2). The body frame is the ADXL345's own frame; a profile says for each chip
// which of its axes, with which sign, is body x, y and z. Chosen with SET_BOARD and kept in EEPROM.
#pragma once
#include <stdint.h>

namespace sphere {

const uint8_t BOARD_ALIGNED = 0, BOARD_SEN10724 = 1, BOARD_GY85 = 2, BOARD_PROFILE_COUNT = 3;
// The profile used while the EEPROM holds none (`make -C firmware BOARD=1` builds an image for a SEN-10724).
#ifndef SPHERE_DEFAULT_BOARD
#define SPHERE_DEFAULT_BOARD 0
#endif
const uint8_t CHIP_ACCEL = 0, CHIP_GYRO = 1, CHIP_MAG = 2;

// One body axis: the chip axis it comes from (bits 0-1: 0 x, 1 y, 2 z) and bit 2 set for a minus sign.
const uint8_t AXIS_NEG = 4;

// Body-frame vector from the chip's x, y, z in place, for `chip` on board `profile` (< BOARD_PROFILE_COUNT).
// The magnetometer's −4096 (the HMC5883L's overflow mark) stays −4096 whatever the sign; any other chip's
// −4096 is a reading and is negated like any other.
void mapAxes(uint8_t profile, uint8_t chip, int16_t v[3]);
// The map itself: three bytes as above.
void axisMap(uint8_t profile, uint8_t chip, uint8_t out[3]);

}  // namespace sphere
