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
        case CMD_SET_BOARD: return 1;
        case CMD_GET_SETTINGS: return 0;
        case CMD_SAVE_SETTINGS: return 0;
        case CMD_CLEAR_SETTINGS: return 0;
        case CMD_SET_BAUD: return 4;
        case CMD_ECHO: return 0;
        default: return -1;
    }
}

static uint8_t copyBody(const void* p, uint8_t len, uint8_t* out) {
    const uint8_t* b = (const uint8_t*)p;
    for (uint8_t i = 0; i < len; ++i) out[i] = b[i];
    return len;
}

uint8_t writeHello(const Hello& p, uint8_t* o) { return copyBody(&p, HELLO_LEN, o); }
uint8_t writeRawSample(const RawSample& p, uint8_t* o) { return copyBody(&p, RAW_SAMPLE_LEN, o); }
uint8_t writeOrientation(const Orientation& p, uint8_t* o) { return copyBody(&p, ORIENTATION_LEN, o); }
uint8_t writeEvent(const Event& p, uint8_t* o) { return copyBody(&p, EVENT_LEN, o); }
uint8_t writeStatus(const Status& p, uint8_t* o) { return copyBody(&p, STATUS_LEN, o); }

uint8_t writeReply(uint8_t cmd_seq, uint8_t cmd_type, uint8_t result, const uint8_t* data, uint8_t data_len,
                   uint8_t* o) {
    o[0] = cmd_seq;
    o[1] = cmd_type;
    o[2] = result;
    for (uint8_t i = 0; i < data_len; ++i) o[3 + i] = data[i];
    return (uint8_t)(3 + data_len);
}

}  // namespace sphere
