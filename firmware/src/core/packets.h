// Packet types and bodies of protocol/spec.md §4–§5 (version 3). Field names are the spec's.
#pragma once
#include <stdint.h>

#include "calibration.h"

namespace sphere {

const uint8_t PROTOCOL_VERSION = 3;
const uint8_t FIRMWARE_VERSION_MAJOR = 0, FIRMWARE_VERSION_MINOR = 3, FIRMWARE_VERSION_PATCH = 3;

enum PacketType : uint8_t {
    PKT_HELLO = 0x01,
    PKT_RAW_SAMPLE = 0x02,
    PKT_ORIENTATION = 0x03,
    PKT_EVENT = 0x04,
    PKT_STATUS = 0x05,
    PKT_REPLY = 0x06,
    CMD_GET_HELLO = 0x40,
    CMD_SET_STREAM = 0x41,
    CMD_SET_TAP = 0x42,
    CMD_SET_FREE_FALL = 0x43,
    CMD_SET_FILTER = 0x44,
    CMD_CALIBRATION_STEP = 0x45,
    CMD_SET_CALIBRATION = 0x46,
    CMD_GET_CALIBRATION = 0x47,
    CMD_SAVE_CALIBRATION = 0x48,
    CMD_LOAD_CALIBRATION = 0x49,
    CMD_RESET_CALIBRATION = 0x4A,
    CMD_IDENTIFY = 0x4B,
    CMD_REBOOT = 0x4C,
    CMD_GET_STATUS = 0x4D,
    CMD_SET_BOARD = 0x4E,
    CMD_SET_BAUD = 0x4F,  // version 3: spec §5.4
    CMD_ECHO = 0x50,      // version 3: spec §5.5
    CMD_GET_SETTINGS = 0x54,
    CMD_SAVE_SETTINGS = 0x55,
    CMD_CLEAR_SETTINGS = 0x56,
};

const uint8_t HELLO_LEN = 22, RAW_SAMPLE_LEN = 23, ORIENTATION_LEN = 13, EVENT_LEN = 8, STATUS_LEN = 29;
const uint8_t REPLY_LEN = 3, REPLY_CALIBRATION_LEN = 3 + CALIBRATION_BLOCK_LEN + 1, REPLY_ECHO_LEN = 3 + 4;
// SET_BAUD (spec §5.4): the rate after power-up and after a fall-back, and how long a faster rate waits
// for the host's first intact frame (200 periods: 1 s) and then between intact frames (300: 1.5 s)
const uint32_t DEFAULT_BAUD = 115200;
const uint16_t BAUD_CONFIRM_TICKS = 200, BAUD_LEASE_TICKS = 300;

// Body length of a packet type, -1 when this firmware does not know the type. REPLY: the length
// without data (3); with GET_CALIBRATION's data it is 46.
int bodyLength(uint8_t type);

// Sensor bits (sensors_found, sensors_ok)
const uint8_t SENSOR_ADXL345 = 1, SENSOR_ITG3200 = 2, SENSOR_HMC5883L = 4;

// RAW_SAMPLE flags
const uint8_t RAW_ACCEL_OK = 1, RAW_GYRO_OK = 2, RAW_MAG_OK = 4, RAW_MAG_FRESH = 8, RAW_TAP_ACTIVE = 16;
// a sensor's value held from its last good read after a failed transaction: RAW_ACCEL_STALE << index
const uint8_t RAW_ACCEL_STALE = 32, RAW_GYRO_STALE = 64, RAW_MAG_STALE = 128;
// ORIENTATION flags
const uint8_t ORI_MAG_USED = 1, ORI_ACCEL_REJECTED = 2, ORI_MAG_REJECTED = 4, ORI_CONVERGING = 8, ORI_GYRO_MISSING = 16;
// bits 5, 6, 7: bits 0, 1, 2 of the update before this one (the period a 100 Hz stream skips)
const uint8_t ORI_PREV_SHIFT = 5;
// EVENT kinds
const uint8_t EVENT_SINGLE_TAP = 1, EVENT_DOUBLE_TAP = 2, EVENT_FREE_FALL = 3;
// stream_mode bits
const uint8_t STREAM_RAW = 1, STREAM_ORIENTATION = 2, STREAM_STATUS = 4;
// calibration_state bits
const uint8_t CAL_GYRO_BIAS_VALID = 1, CAL_ACCEL_CALIBRATED = 2, CAL_MAG_CALIBRATED = 4, CAL_FROM_EEPROM = 8,
              CAL_EEPROM_INVALID = 16, CAL_GYRO_BIAS_ESTIMATED = 32;
// HELLO reset_cause bits (the ATmega328P's MCUSR: PORF, EXTRF, BORF, WDRF)
const uint8_t RESET_POWER_ON = 1, RESET_EXTERNAL = 2, RESET_BROWN_OUT = 4, RESET_WATCHDOG = 8;
// HELLO mag_chip
const uint8_t MAG_CHIP_NONE = 0, MAG_CHIP_HMC5883L = 1, MAG_CHIP_QMC5883L = 2;

struct __attribute__((packed)) Hello {
    uint8_t protocol_version;
    uint8_t firmware_version[3];
    uint8_t sensors_found;
    uint8_t adxl345_devid;
    uint8_t itg3200_whoami;
    uint8_t hmc5883l_id[3];
    uint16_t imu_rate_hz;
    uint8_t mag_rate_hz;
    uint8_t stream_mode;
    uint16_t raw_rate_hz;
    uint16_t orientation_rate_hz;
    uint8_t calibration_state;
    uint8_t reset_cause;
    uint8_t mag_chip;
    uint8_t board_profile;
};

struct __attribute__((packed)) RawSample {
    uint32_t t_us;
    uint8_t flags;
    int16_t accel[3];
    int16_t gyro[3];
    int16_t mag[3];
};

struct __attribute__((packed)) Orientation {
    uint32_t t_us;
    uint8_t flags;
    int16_t quat[4];  // Q14, w x y z, sensor → earth (NWU)
};

struct __attribute__((packed)) Event {
    uint32_t t_us;
    uint8_t event;
    uint8_t int_source;
    uint8_t act_tap_status;
    int8_t tap_sign;
};

struct __attribute__((packed)) Status {
    uint32_t t_us;
    uint8_t sensors_ok;
    uint16_t i2c_errors[3];
    uint16_t i2c_recoveries;
    uint16_t loop_overruns;
    uint16_t frames_dropped;
    uint16_t rx_errors;
    uint8_t calibration_state;
    uint8_t calibration_step;
    uint16_t cpu_load;
    uint16_t battery_mv;
    uint16_t probe_failures;
    uint16_t sensor_losses;
};

// The packet structs are packed and little-endian on both the ATmega328P and the native test hosts,
// so their bytes are the bodies of §4 as they stand (checked below and by the golden vectors).
static_assert(sizeof(Hello) == HELLO_LEN, "HELLO body is 22 bytes");
static_assert(sizeof(RawSample) == RAW_SAMPLE_LEN, "RAW_SAMPLE body is 23 bytes");
static_assert(sizeof(Orientation) == ORIENTATION_LEN, "ORIENTATION body is 13 bytes");
static_assert(sizeof(Event) == EVENT_LEN, "EVENT body is 8 bytes");
static_assert(sizeof(Status) == STATUS_LEN, "STATUS body is 29 bytes");
#if defined(__BYTE_ORDER__) && __BYTE_ORDER__ != __ORDER_LITTLE_ENDIAN__
#error "packet bodies are copied from packed structs: a little-endian target is required"
#endif

// Each writes the body into `out` and returns its length.
uint8_t writeHello(const Hello& p, uint8_t* out);
uint8_t writeRawSample(const RawSample& p, uint8_t* out);
uint8_t writeOrientation(const Orientation& p, uint8_t* out);
uint8_t writeEvent(const Event& p, uint8_t* out);
uint8_t writeStatus(const Status& p, uint8_t* out);
// REPLY; `data` may be null when data_len is 0.
uint8_t writeReply(uint8_t cmd_seq, uint8_t cmd_type, uint8_t result, const uint8_t* data, uint8_t data_len,
                   uint8_t* out);

}  // namespace sphere
