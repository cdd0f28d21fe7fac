// Host → device commands (protocol/spec.md §5): checks type, body length and field ranges and
// gives either a Command to carry out or the REPLY result code that refuses it. A refused command
// changes nothing. Checks that need device state (busy, sensor_missing, storage_error) are the
// device's (SphereDevice), after parsing.
#pragma once
#include <stdint.h>

#include "calibration.h"

namespace sphere {

enum ResultCode : uint8_t {
    RESULT_OK = 0,
    RESULT_UNKNOWN_COMMAND = 1,
    RESULT_BAD_LENGTH = 2,
    RESULT_BAD_VALUE = 3,
    RESULT_BUSY = 4,
    RESULT_SENSOR_MISSING = 5,
    RESULT_STORAGE_ERROR = 6,
    RESULT_FAILED = 7,
};

const uint16_t IMU_RATE_HZ = 200;
const uint16_t REBOOT_MAGIC = 0xB007;
const uint16_t BETA_MAX_MILLI = 2000;

struct Command {
    uint8_t type;
    uint8_t seq;
    union {
        struct { uint8_t stream_mode; uint16_t raw_rate_hz; uint16_t orientation_rate_hz; } set_stream;
        struct { uint8_t thresh_tap, dur, latent, window, tap_axes; } set_tap;
        struct { uint8_t thresh_ff, time_ff; } set_free_fall;
        struct { uint16_t beta; } set_filter;  // 1/1000 per LSB
        struct { uint8_t step, action; } calibration_step;
        struct { uint8_t seconds; } identify;
        struct { uint16_t magic; } reboot;
        struct { uint8_t board_profile; } set_board;
        struct { uint32_t baud; } set_baud;
    };
    Calibration calibration;  // SET_CALIBRATION
};

class CommandParser {
public:
    // `payload` is a CRC-good decoded payload (type, seq, body, crc) of `len` bytes (≥ 4).
    static ResultCode parse(const uint8_t* payload, uint8_t len, Command& cmd);
    // A stream rate is valid when it divides IMU_RATE_HZ, or is 0 when its stream is off.
    static bool rateValid(uint16_t rate_hz, bool enabled);
};

}  // namespace sphere
