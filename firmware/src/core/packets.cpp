#include "packets.h"

#include "bytes.h"

namespace sphere {

int bodyLength(uint8_t type) {
    switch (type) {
        case PKT_HELLO: return HELLO_LEN;
        case PKT_RAW_SAMPLE: return RAW_SAMPLE_LEN;
        case PKT_ORIENTATION: return ORIENTATION_LEN;
        case PKT_EVENT: return EVENT_LEN;
        case PKT_STATUS: return STATUS_LEN;
        case PKT_REPLY: return REPLY_LEN;
        case CMD_GET_HELLO: return 0;
        case CMD_SET_STREAM: return 5;
        case CMD_SET_TAP: return 5;
        case CMD_SET_FREE_FALL: return 2;
        case CMD_SET_FILTER: return 2;
        case CMD_CALIBRATION_STEP: return 2;
        case CMD_SET_CALIBRATION: return CALIBRATION_BLOCK_LEN;
        case CMD_GET_CALIBRATION: return 0;
        case CMD_SAVE_CALIBRATION: return 0;
        case CMD_LOAD_CALIBRATION: return 0;
        case CMD_RESET_CALIBRATION: return 0;
        case CMD_IDENTIFY: return 1;
        case CMD_REBOOT: return 2;
        case CMD_GET_STATUS: return 0;
        default: return -1;
    }
}

uint8_t writeHello(const Hello& p, uint8_t* o) {
    o[0] = p.protocol_version;
    o[1] = p.firmware_version[0];
    o[2] = p.firmware_version[1];
    o[3] = p.firmware_version[2];
    o[4] = p.sensors_found;
    o[5] = p.adxl345_devid;
    o[6] = p.itg3200_whoami;
    o[7] = p.hmc5883l_id[0];
    o[8] = p.hmc5883l_id[1];
    o[9] = p.hmc5883l_id[2];
    putU16(o + 10, p.imu_rate_hz);
    o[12] = p.mag_rate_hz;
    o[13] = p.stream_mode;
    putU16(o + 14, p.raw_rate_hz);
    putU16(o + 16, p.orientation_rate_hz);
    o[18] = p.calibration_state;
    return HELLO_LEN;
}

uint8_t writeRawSample(const RawSample& p, uint8_t* o) {
    putU32(o, p.t_us);
    o[4] = p.flags;
    for (uint8_t i = 0; i < 3; ++i) {
        putI16(o + 5 + 2 * i, p.accel[i]);
        putI16(o + 11 + 2 * i, p.gyro[i]);
        putI16(o + 17 + 2 * i, p.mag[i]);
    }
    return RAW_SAMPLE_LEN;
}

uint8_t writeOrientation(const Orientation& p, uint8_t* o) {
    putU32(o, p.t_us);
    o[4] = p.flags;
    for (uint8_t i = 0; i < 4; ++i) putI16(o + 5 + 2 * i, p.quat[i]);
    return ORIENTATION_LEN;
}

uint8_t writeEvent(const Event& p, uint8_t* o) {
    putU32(o, p.t_us);
    o[4] = p.event;
    o[5] = p.int_source;
    o[6] = p.act_tap_status;
    o[7] = (uint8_t)p.tap_sign;
    return EVENT_LEN;
}

uint8_t writeStatus(const Status& p, uint8_t* o) {
    putU32(o, p.t_us);
    o[4] = p.sensors_ok;
    for (uint8_t i = 0; i < 3; ++i) putU16(o + 5 + 2 * i, p.i2c_errors[i]);
    putU16(o + 11, p.i2c_recoveries);
    putU16(o + 13, p.loop_overruns);
    putU16(o + 15, p.frames_dropped);
    putU16(o + 17, p.rx_errors);
    o[19] = p.calibration_state;
    o[20] = p.calibration_step;
    putU16(o + 21, p.cpu_load);
    putU16(o + 23, p.battery_mv);
    return STATUS_LEN;
}

uint8_t writeReply(uint8_t cmd_seq, uint8_t cmd_type, uint8_t result, const uint8_t* data, uint8_t data_len,
                   uint8_t* o) {
    o[0] = cmd_seq;
    o[1] = cmd_type;
    o[2] = result;
    for (uint8_t i = 0; i < data_len; ++i) o[3 + i] = data[i];
    return (uint8_t)(3 + data_len);
}

}  // namespace sphere
