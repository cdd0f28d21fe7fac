#include "command_parser.h"

#include "board_profile.h"
#include "bytes.h"
#include "packets.h"

namespace sphere {

bool CommandParser::rateValid(uint16_t rate_hz, bool enabled) {
    if (!enabled) return rate_hz == 0;
    return rate_hz != 0 && rate_hz <= IMU_RATE_HZ && IMU_RATE_HZ % rate_hz == 0;
}

ResultCode CommandParser::parse(const uint8_t* payload, uint8_t len, Command& cmd) {
    cmd.type = payload[0];
    cmd.seq = payload[1];
    const uint8_t* b = payload + 2;
    uint8_t n = (uint8_t)(len - 4);
    if (cmd.type < 0x40 || cmd.type > 0x7F) return RESULT_UNKNOWN_COMMAND;
    int expect = bodyLength(cmd.type);
    if (expect < 0) return RESULT_UNKNOWN_COMMAND;
    if (n != expect) return RESULT_BAD_LENGTH;
    switch (cmd.type) {
        case CMD_SET_STREAM: {
            uint8_t mode = b[0];
            uint16_t raw = getU16(b + 1), ori = getU16(b + 3);
            if (mode & ~(STREAM_RAW | STREAM_ORIENTATION | STREAM_STATUS)) return RESULT_BAD_VALUE;
            if (!rateValid(raw, mode & STREAM_RAW) || !rateValid(ori, mode & STREAM_ORIENTATION))
                return RESULT_BAD_VALUE;
            cmd.set_stream.stream_mode = mode;
            cmd.set_stream.raw_rate_hz = raw;
            cmd.set_stream.orientation_rate_hz = ori;
            break;
        }
        case CMD_SET_TAP:
            if (b[0] < 1 || b[1] < 1 || (b[4] & 0xF0)) return RESULT_BAD_VALUE;
            cmd.set_tap.thresh_tap = b[0];
            cmd.set_tap.dur = b[1];
            cmd.set_tap.latent = b[2];
            cmd.set_tap.window = b[3];
            cmd.set_tap.tap_axes = b[4];
            break;
        case CMD_SET_FREE_FALL:
            if (b[0] < 1 || b[1] < 1) return RESULT_BAD_VALUE;
            cmd.set_free_fall.thresh_ff = b[0];
            cmd.set_free_fall.time_ff = b[1];
            break;
        case CMD_SET_FILTER: {
            uint16_t beta = getU16(b);
            if (beta > BETA_MAX_MILLI) return RESULT_BAD_VALUE;
            cmd.set_filter.beta = beta;
            break;
        }
        case CMD_CALIBRATION_STEP:
            if (b[0] < 1 || b[0] > 3 || b[1] > 1) return RESULT_BAD_VALUE;
            cmd.calibration_step.step = b[0];
            cmd.calibration_step.action = b[1];
            break;
        case CMD_SET_CALIBRATION:
            readCalibrationBlock(b, cmd.calibration);
            if (!cmd.calibration.valid()) return RESULT_BAD_VALUE;
            break;
        case CMD_SET_BOARD:
            if (b[0] >= BOARD_PROFILE_COUNT) return RESULT_BAD_VALUE;
            cmd.set_board.board_profile = b[0];
            break;
        case CMD_SET_BAUD: {  // the rates exact on 16 MHz, and the default (spec §5.4)
            uint32_t baud = getU32(b);
            if (baud != DEFAULT_BAUD && baud != 250000 && baud != 500000 && baud != 1000000) return RESULT_BAD_VALUE;
            cmd.set_baud.baud = baud;
            break;
        }
        case CMD_IDENTIFY:
            if (b[0] < 1 || b[0] > 60) return RESULT_BAD_VALUE;
            cmd.identify.seconds = b[0];
            break;
        case CMD_REBOOT: {
            uint16_t magic = getU16(b);
            if (magic != REBOOT_MAGIC) return RESULT_BAD_VALUE;
            cmd.reboot.magic = magic;
            break;
        }
        default:
            break;  // no body
    }
    return RESULT_OK;
}

}  // namespace sphere
