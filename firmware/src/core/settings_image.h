// The device settings a user changes (protocol/spec.md §5.3): one block made of the bodies of SET_STREAM,
// SET_TAP, SET_FREE_FALL and SET_FILTER in that order, so a saved block is checked and applied by the same
// parser and code as the commands; and its EEPROM image (format version byte, block, CRC-16/CCITT-FALSE over
// version + block), as the calibration's.
#pragma once
#include <stdint.h>

namespace sphere {

const uint8_t SETTINGS_GROUPS = 4;
// the command whose body each part of the block is, and that body's length
extern const uint8_t SETTINGS_GROUP_TYPE[SETTINGS_GROUPS];
extern const uint8_t SETTINGS_GROUP_LEN[SETTINGS_GROUPS];
const uint8_t SETTINGS_BLOCK_LEN = 5 + 5 + 2 + 2;
const uint8_t SETTINGS_EEPROM_VERSION = 1;
const uint8_t SETTINGS_EEPROM_LEN = 1 + SETTINGS_BLOCK_LEN + 2;  // version, block, crc (LE)
const uint16_t SETTINGS_EEPROM_ADDR = 80;  // after the calibration (0 … 44) and the board profile (64, 65)

// settings_state bits (GET_SETTINGS)
const uint8_t SETTINGS_SAVED = 1;           // the settings in use are the ones saved
const uint8_t SETTINGS_EEPROM_INVALID = 2;  // at power-up the saved block was corrupt: firmware defaults in use
const uint8_t SETTINGS_NONE_SAVED = 4;      // nothing (valid) saved: the next power-up uses the firmware defaults

enum SettingsImage : uint8_t { SETTINGS_IMAGE_VALID, SETTINGS_IMAGE_BLANK, SETTINGS_IMAGE_CORRUPT };

void writeSettingsImage(const uint8_t block[SETTINGS_BLOCK_LEN], uint8_t image[SETTINGS_EEPROM_LEN]);
// VALID (block filled: version and CRC right; the values are the parser's to check), BLANK (every byte
// 0xFF: an erased EEPROM, nothing ever saved) or CORRUPT.
SettingsImage readSettingsImage(const uint8_t image[SETTINGS_EEPROM_LEN], uint8_t block[SETTINGS_BLOCK_LEN]);

}  // namespace sphere
