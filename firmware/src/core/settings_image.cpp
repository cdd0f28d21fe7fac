#include "settings_image.h"

#include "bytes.h"
#include "crc16.h"
#include "packets.h"

namespace sphere {

const uint8_t SETTINGS_GROUP_TYPE[SETTINGS_GROUPS] = {CMD_SET_STREAM, CMD_SET_TAP, CMD_SET_FREE_FALL, CMD_SET_FILTER};
const uint8_t SETTINGS_GROUP_LEN[SETTINGS_GROUPS] = {5, 5, 2, 2};

void writeSettingsImage(const uint8_t block[SETTINGS_BLOCK_LEN], uint8_t image[SETTINGS_EEPROM_LEN]) {
    image[0] = SETTINGS_EEPROM_VERSION;
    for (uint8_t i = 0; i < SETTINGS_BLOCK_LEN; ++i) image[1 + i] = block[i];
    putU16(image + 1 + SETTINGS_BLOCK_LEN, crc16(image, 1 + SETTINGS_BLOCK_LEN));
}

SettingsImage readSettingsImage(const uint8_t image[SETTINGS_EEPROM_LEN], uint8_t block[SETTINGS_BLOCK_LEN]) {
    uint8_t all = 0xFF;
    for (uint8_t i = 0; i < SETTINGS_EEPROM_LEN; ++i) all &= image[i];
    if (all == 0xFF) return SETTINGS_IMAGE_BLANK;
    if (image[0] != SETTINGS_EEPROM_VERSION) return SETTINGS_IMAGE_CORRUPT;
    if (crc16(image, 1 + SETTINGS_BLOCK_LEN) != getU16(image + 1 + SETTINGS_BLOCK_LEN)) return SETTINGS_IMAGE_CORRUPT;
    for (uint8_t i = 0; i < SETTINGS_BLOCK_LEN; ++i) block[i] = image[1 + i];
    return SETTINGS_IMAGE_VALID;
}

}  // namespace sphere
