// Framing, packet bodies and command parsing against protocol/vectors/frames.txt.
#include <cstring>
#include <functional>

#include "doctest_include.h"

#include "bytes.h"
#include "command_parser.h"
#include "crc16.h"
#include "framing.h"
#include "packets.h"
#include "test_paths.h"
#include "vectors.h"

using namespace sphere;

namespace {

struct FieldSpec {
    const char* name;
    char kind;  // 'B' u8, 'b' i8, 'H' u16, 'h' i16, 'I' u32
    int count;
};

const std::map<std::string, std::pair<uint8_t, std::vector<FieldSpec>>>& layouts() {
    static const std::map<std::string, std::pair<uint8_t, std::vector<FieldSpec>>> L = {
        {"HELLO", {PKT_HELLO, {{"protocol_version", 'B', 1}, {"firmware_version", 'B', 3}, {"sensors_found", 'B', 1},
                               {"adxl345_devid", 'B', 1}, {"itg3200_whoami", 'B', 1}, {"hmc5883l_id", 'B', 3},
                               {"imu_rate_hz", 'H', 1}, {"mag_rate_hz", 'B', 1}, {"stream_mode", 'B', 1},
                               {"raw_rate_hz", 'H', 1}, {"orientation_rate_hz", 'H', 1},
                               {"calibration_state", 'B', 1}, {"reset_cause", 'B', 1}, {"mag_chip", 'B', 1},
                               {"board_profile", 'B', 1}}}},
        {"RAW_SAMPLE", {PKT_RAW_SAMPLE, {{"t_us", 'I', 1}, {"flags", 'B', 1}, {"accel", 'h', 3}, {"gyro", 'h', 3},
                                         {"mag", 'h', 3}}}},
        {"ORIENTATION", {PKT_ORIENTATION, {{"t_us", 'I', 1}, {"flags", 'B', 1}, {"quat", 'h', 4}}}},
        {"EVENT", {PKT_EVENT, {{"t_us", 'I', 1}, {"event", 'B', 1}, {"int_source", 'B', 1},
                               {"act_tap_status", 'B', 1}, {"tap_sign", 'b', 1}}}},
        {"STATUS", {PKT_STATUS, {{"t_us", 'I', 1}, {"sensors_ok", 'B', 1}, {"i2c_errors", 'H', 3},
                                 {"i2c_recoveries", 'H', 1}, {"loop_overruns", 'H', 1}, {"frames_dropped", 'H', 1},
                                 {"rx_errors", 'H', 1}, {"calibration_state", 'B', 1}, {"calibration_step", 'B', 1},
                                 {"cpu_load", 'H', 1}, {"battery_mv", 'H', 1}, {"probe_failures", 'H', 1},
                                 {"sensor_losses", 'H', 1}}}},
        {"REPLY", {PKT_REPLY, {{"cmd_seq", 'B', 1}, {"cmd_type", 'B', 1}, {"result", 'B', 1}}}},
        {"GET_HELLO", {CMD_GET_HELLO, {}}},
        {"SET_STREAM", {CMD_SET_STREAM, {{"stream_mode", 'B', 1}, {"raw_rate_hz", 'H', 1},
                                         {"orientation_rate_hz", 'H', 1}}}},
        {"SET_TAP", {CMD_SET_TAP, {{"thresh_tap", 'B', 1}, {"dur", 'B', 1}, {"latent", 'B', 1}, {"window", 'B', 1},
                                   {"tap_axes", 'B', 1}}}},
        {"SET_FREE_FALL", {CMD_SET_FREE_FALL, {{"thresh_ff", 'B', 1}, {"time_ff", 'B', 1}}}},
        {"SET_FILTER", {CMD_SET_FILTER, {{"beta", 'H', 1}}}},
        {"CALIBRATION_STEP", {CMD_CALIBRATION_STEP, {{"step", 'B', 1}, {"action", 'B', 1}}}},
        {"SET_CALIBRATION", {CMD_SET_CALIBRATION, {{"gyro_bias", 'h', 3}, {"accel_offset", 'h', 3},
                                                   {"accel_scale", 'h', 3}, {"mag_offset", 'h', 3},
                                                   {"mag_soft_iron", 'h', 9}}}},
        {"GET_CALIBRATION", {CMD_GET_CALIBRATION, {}}},
        {"SAVE_CALIBRATION", {CMD_SAVE_CALIBRATION, {}}},
        {"LOAD_CALIBRATION", {CMD_LOAD_CALIBRATION, {}}},
        {"RESET_CALIBRATION", {CMD_RESET_CALIBRATION, {}}},
        {"IDENTIFY", {CMD_IDENTIFY, {{"seconds", 'B', 1}}}},
        {"REBOOT", {CMD_REBOOT, {{"magic", 'H', 1}}}},
        {"GET_STATUS", {CMD_GET_STATUS, {}}},
        {"SET_BOARD", {CMD_SET_BOARD, {{"board_profile", 'B', 1}}}},
        {"GET_SETTINGS", {CMD_GET_SETTINGS, {}}},
        {"SAVE_SETTINGS", {CMD_SAVE_SETTINGS, {}}},
        {"CLEAR_SETTINGS", {CMD_CLEAR_SETTINGS, {}}},
        {"SET_BAUD", {CMD_SET_BAUD, {{"baud", 'I', 1}}}},
        {"ECHO", {CMD_ECHO, {}}},
    };
    return L;
}

int kindSize(char k) { return k == 'I' ? 4 : (k == 'H' || k == 'h') ? 2 : 1; }

// decodes the body by layout into name → values
std::map<std::string, std::vector<long>> decodeBody(const std::vector<FieldSpec>& spec, const uint8_t* b, size_t n,
                                                    size_t* used) {
    std::map<std::string, std::vector<long>> out;
    size_t o = 0;
    for (const auto& f : spec)
        for (int i = 0; i < f.count; ++i) {
            long v = 0;
            switch (f.kind) {
                case 'B': v = b[o]; break;
                case 'b': v = (int8_t)b[o]; break;
                case 'H': v = getU16(b + o); break;
                case 'h': v = getI16(b + o); break;
                case 'I': v = (long)getU32(b + o); break;
            }
            o += kindSize(f.kind);
            out[f.name].push_back(v);
        }
    *used = o;
    return out;
}

std::vector<uint8_t> encodeBody(const std::vector<FieldSpec>& spec, const Vector& v) {
    std::vector<uint8_t> out;
    for (const auto& f : spec) {
        auto vals = parseInts(v.get(f.name));
        REQUIRE_MESSAGE((int)vals.size() == f.count, v.name << ": field " << f.name);
        for (long x : vals) {
            int n = kindSize(f.kind);
            for (int i = 0; i < n; ++i) out.push_back((uint8_t)((unsigned long)x >> (8 * i)));
        }
    }
    return out;
}

long field1(const Vector& v, const char* k) { return parseInts(v.get(k)).at(0); }

// Build the device's packet struct from the vector's fields and encode with the firmware's writer.
std::vector<uint8_t> firmwareBody(const std::string& type, const Vector& v) {
    uint8_t body[MAX_BODY];
    uint8_t n = 0;
    auto arr = [&](const char* k, int i) { return parseInts(v.get(k)).at(i); };
    if (type == "HELLO") {
        Hello p;
        p.protocol_version = (uint8_t)field1(v, "protocol_version");
        for (int i = 0; i < 3; ++i) p.firmware_version[i] = (uint8_t)arr("firmware_version", i);
        p.sensors_found = (uint8_t)field1(v, "sensors_found");
        p.adxl345_devid = (uint8_t)field1(v, "adxl345_devid");
        p.itg3200_whoami = (uint8_t)field1(v, "itg3200_whoami");
        for (int i = 0; i < 3; ++i) p.hmc5883l_id[i] = (uint8_t)arr("hmc5883l_id", i);
        p.imu_rate_hz = (uint16_t)field1(v, "imu_rate_hz");
        p.mag_rate_hz = (uint8_t)field1(v, "mag_rate_hz");
        p.stream_mode = (uint8_t)field1(v, "stream_mode");
        p.raw_rate_hz = (uint16_t)field1(v, "raw_rate_hz");
        p.orientation_rate_hz = (uint16_t)field1(v, "orientation_rate_hz");
        p.calibration_state = (uint8_t)field1(v, "calibration_state");
        p.reset_cause = (uint8_t)field1(v, "reset_cause");
        p.mag_chip = (uint8_t)field1(v, "mag_chip");
        p.board_profile = (uint8_t)field1(v, "board_profile");
        n = writeHello(p, body);
    } else if (type == "RAW_SAMPLE") {
        RawSample p;
        p.t_us = (uint32_t)field1(v, "t_us");
        p.flags = (uint8_t)field1(v, "flags");
        for (int i = 0; i < 3; ++i) {
            p.accel[i] = (int16_t)arr("accel", i);
            p.gyro[i] = (int16_t)arr("gyro", i);
            p.mag[i] = (int16_t)arr("mag", i);
        }
        n = writeRawSample(p, body);
    } else if (type == "ORIENTATION") {
        Orientation p;
        p.t_us = (uint32_t)field1(v, "t_us");
        p.flags = (uint8_t)field1(v, "flags");
        for (int i = 0; i < 4; ++i) p.quat[i] = (int16_t)arr("quat", i);
        n = writeOrientation(p, body);
    } else if (type == "EVENT") {
        Event p;
        p.t_us = (uint32_t)field1(v, "t_us");
        p.event = (uint8_t)field1(v, "event");
        p.int_source = (uint8_t)field1(v, "int_source");
        p.act_tap_status = (uint8_t)field1(v, "act_tap_status");
        p.tap_sign = (int8_t)field1(v, "tap_sign");
        n = writeEvent(p, body);
    } else if (type == "STATUS") {
        Status p;
        p.t_us = (uint32_t)field1(v, "t_us");
        p.sensors_ok = (uint8_t)field1(v, "sensors_ok");
        for (int i = 0; i < 3; ++i) p.i2c_errors[i] = (uint16_t)arr("i2c_errors", i);
        p.i2c_recoveries = (uint16_t)field1(v, "i2c_recoveries");
        p.loop_overruns = (uint16_t)field1(v, "loop_overruns");
        p.frames_dropped = (uint16_t)field1(v, "frames_dropped");
        p.rx_errors = (uint16_t)field1(v, "rx_errors");
        p.calibration_state = (uint8_t)field1(v, "calibration_state");
        p.calibration_step = (uint8_t)field1(v, "calibration_step");
        p.cpu_load = (uint16_t)field1(v, "cpu_load");
        p.battery_mv = (uint16_t)field1(v, "battery_mv");
        p.probe_failures = (uint16_t)field1(v, "probe_failures");
        p.sensor_losses = (uint16_t)field1(v, "sensor_losses");
        n = writeStatus(p, body);
    } else if (type == "REPLY") {
        auto data = parseHex(v.get("data"));
        n = writeReply((uint8_t)field1(v, "cmd_seq"), (uint8_t)field1(v, "cmd_type"), (uint8_t)field1(v, "result"),
                       data.data(), (uint8_t)data.size(), body);
    }
    return std::vector<uint8_t>(body, body + n);
}

struct Decoded {
    FrameResult result;
    std::vector<uint8_t> payload;
};

Decoded runDecoder(FrameDecoder& d, const std::vector<uint8_t>& wire) {
    Decoded out{FRAME_NONE, {}};
    for (uint8_t b : wire) {
        FrameResult r = d.push(b);
        if (r != FRAME_NONE) {
            out.result = r;
            if (r == FRAME_OK) out.payload.assign(d.payload(), d.payload() + d.payloadLength());
        }
    }
    return out;
}

// The REPLY result the device gives each host-direction vector (spec §5, §5.1).
uint8_t expectedReplyResult(const Vector& v) {
    if (v.name == "cmd_set_stream_bad_rate" || v.name == "cmd_set_baud_bad_rate") return RESULT_BAD_VALUE;
    std::string o = v.get("outcome");
    if (o == "bad_length") return RESULT_BAD_LENGTH;
    if (o == "unknown_type") return RESULT_UNKNOWN_COMMAND;
    return RESULT_OK;
}

}  // namespace

TEST_CASE("CRC-16/CCITT-FALSE check value") {
    const char* s = "123456789";
    CHECK(crc16((const uint8_t*)s, 9) == 0x29B1);
}

TEST_CASE("COBS round trip on every length with zeros, and 254-byte runs") {
    for (int len = 0; len < 300; ++len) {
        std::vector<uint8_t> in(len), enc(len + len / 254 + 2), dec(len + 1);
        for (int i = 0; i < len; ++i) in[i] = (uint8_t)((i * 37 + len) % 7 == 0 ? 0 : i * 13 + 1);
        size_t n = cobsEncode(in.data(), len, enc.data());
        CHECK(n <= (size_t)len + len / 254 + 1);
        for (size_t i = 0; i < n; ++i) CHECK(enc[i] != 0);
        int m = cobsDecode(enc.data(), n, dec.data(), dec.size());
        REQUIRE(m == len);
        CHECK(std::equal(in.begin(), in.end(), dec.begin()));
    }
}

TEST_CASE("every golden vector decodes, re-encodes and is judged as listed") {
    auto vectors = loadVectors(repoPath("protocol/vectors/frames.txt"));
    REQUIRE(vectors.size() >= 30);
    int ok = 0, broken = 0, host = 0;
    for (const Vector& v : vectors) {
        CAPTURE(v.name);
        std::string outcome = v.get("outcome"), dir = v.get("direction");
        REQUIRE(!v.wire.empty());
        FrameDecoder d;
        Decoded r = runDecoder(d, v.wire);
        if (outcome == "oversize") {
            CHECK(r.result == FRAME_OVERSIZE);
            CHECK(d.oversize == 1);
            CHECK(d.bytes_skipped == v.wire.size());
            ++broken;
            continue;
        }
        if (outcome == "framing_error") {
            CHECK(r.result == FRAME_FRAMING_ERROR);
            CHECK(d.framing_errors == 1);
            ++broken;
            continue;
        }
        if (outcome == "crc_error") {
            CHECK(r.result == FRAME_CRC_ERROR);
            CHECK(d.crc_errors == 1);
            ++broken;
            continue;
        }
        REQUIRE(r.result == FRAME_OK);
        uint8_t type = r.payload[0], seq = r.payload[1];
        CHECK(seq == field1(v, "seq"));
        size_t body_len = r.payload.size() - 4;
        const uint8_t* body = r.payload.data() + 2;
        std::string tname = v.get("type");
        if (outcome == "unknown_type") {
            CHECK(type == std::stol(tname, nullptr, 0));
            if (dir == "device") CHECK(bodyLength(type) < 0);
        } else {
            auto it = layouts().find(tname);
            REQUIRE_MESSAGE(it != layouts().end(), "type " << tname);
            CHECK(type == it->second.first);
            if (outcome == "bad_length") {
                CHECK(bodyLength(type) >= 0);
                CHECK((int)body_len != bodyLength(type));
            } else {
                size_t used = 0;
                auto fields = decodeBody(it->second.second, body, body_len, &used);
                for (const auto& f : fields) CHECK_MESSAGE(f.second == parseInts(v.get(f.first)), f.first);
                if (tname == "REPLY") {
                    auto data = parseHex(v.get("data"));
                    CHECK(std::vector<uint8_t>(body + used, body + body_len) == data);
                    used += data.size();
                }
                CHECK(used == body_len);
                // re-encode with the firmware's writers (device) or from the fields (host)
                std::vector<uint8_t> b = dir == "device" ? firmwareBody(tname, v) : encodeBody(it->second.second, v);
                uint8_t out[MAX_FRAME];
                size_t n = FrameEncoder::encodeWithSeq(type, seq, b.data(), (uint8_t)b.size(), out);
                CHECK(std::vector<uint8_t>(out, out + n) == v.wire);
                ++ok;
            }
        }
        if (dir == "host") {
            // the reply the device sends
            ++host;
            Command cmd;
            uint8_t result = CommandParser::parse(r.payload.data(), (uint8_t)r.payload.size(), cmd);
            CHECK(result == expectedReplyResult(v));
            CHECK(cmd.seq == seq);
            CHECK(cmd.type == type);
            if (result == RESULT_OK) {
                auto it = layouts().find(tname);
                REQUIRE(it != layouts().end());
                if (tname == "SET_STREAM") {
                    CHECK(cmd.set_stream.stream_mode == field1(v, "stream_mode"));
                    CHECK(cmd.set_stream.raw_rate_hz == field1(v, "raw_rate_hz"));
                    CHECK(cmd.set_stream.orientation_rate_hz == field1(v, "orientation_rate_hz"));
                } else if (tname == "SET_TAP") {
                    CHECK(cmd.set_tap.thresh_tap == field1(v, "thresh_tap"));
                    CHECK(cmd.set_tap.dur == field1(v, "dur"));
                    CHECK(cmd.set_tap.latent == field1(v, "latent"));
                    CHECK(cmd.set_tap.window == field1(v, "window"));
                    CHECK(cmd.set_tap.tap_axes == field1(v, "tap_axes"));
                } else if (tname == "SET_FREE_FALL") {
                    CHECK(cmd.set_free_fall.thresh_ff == field1(v, "thresh_ff"));
                    CHECK(cmd.set_free_fall.time_ff == field1(v, "time_ff"));
                } else if (tname == "SET_FILTER") {
                    CHECK(cmd.set_filter.beta == field1(v, "beta"));
                } else if (tname == "CALIBRATION_STEP") {
                    CHECK(cmd.calibration_step.step == field1(v, "step"));
                    CHECK(cmd.calibration_step.action == field1(v, "action"));
                } else if (tname == "IDENTIFY") {
                    CHECK(cmd.identify.seconds == field1(v, "seconds"));
                } else if (tname == "REBOOT") {
                    CHECK(cmd.reboot.magic == field1(v, "magic"));
                } else if (tname == "SET_BAUD") {
                    CHECK(cmd.set_baud.baud == (uint32_t)field1(v, "baud"));
                } else if (tname == "SET_CALIBRATION") {
                    uint8_t blk[CALIBRATION_BLOCK_LEN];
                    writeCalibrationBlock(cmd.calibration, blk);
                    CHECK(std::vector<uint8_t>(blk, blk + CALIBRATION_BLOCK_LEN) ==
                          std::vector<uint8_t>(body, body + body_len));
                    CHECK((int)cmd.calibration.mag_soft_iron[1] == -120);
                }
            }
            // the REPLY frame itself decodes back to what was sent
            uint8_t rb[8], wire[MAX_FRAME];
            uint8_t rn = writeReply(seq, type, result, nullptr, 0, rb);
            size_t wn = FrameEncoder::encodeWithSeq(PKT_REPLY, 77, rb, rn, wire);
            FrameDecoder d2;
            Decoded back = runDecoder(d2, std::vector<uint8_t>(wire, wire + wn));
            REQUIRE(back.result == FRAME_OK);
            CHECK(back.payload[2] == seq);
            CHECK(back.payload[3] == type);
            CHECK(back.payload[4] == result);
        }
    }
    MESSAGE(ok << " vectors decoded and re-encoded, " << broken << " broken ones judged, " << host
               << " host commands answered");
    CHECK(broken == 5);
}

TEST_CASE("the frame after garbage is always decoded; counters per §2.1") {
    auto vectors = loadVectors(repoPath("protocol/vectors/frames.txt"));
    std::vector<uint8_t> stream, good;
    for (const auto& v : vectors)
        if (v.name == "raw_sample") good = v.wire;
    REQUIRE(!good.empty());
    for (const auto& v : vectors)
        if (v.get("outcome") != "ok") stream.insert(stream.end(), v.wire.begin(), v.wire.end());
    std::vector<uint8_t> junk(200, 0x55);  // very long chunk
    stream.insert(stream.end(), junk.begin(), junk.end());
    stream.push_back(0);
    stream.push_back(0);  // empty frame: nothing
    stream.insert(stream.end(), good.begin(), good.end());
    FrameDecoder d;
    int oks = 0;
    for (uint8_t b : stream)
        if (d.push(b) == FRAME_OK) ++oks;
    // unknown_type, bad_length, cmd_bad_length, cmd_unknown_type are CRC-good, then the raw sample
    CHECK(oks == 5);
    CHECK(d.type() == PKT_RAW_SAMPLE);
    CHECK(d.oversize == 2);
    CHECK(d.crc_errors == 2);
    CHECK(d.framing_errors == 2);
}

TEST_CASE("command ranges: an invalid command gets a reason") {
    auto payload = [](uint8_t type, std::vector<uint8_t> body) {
        std::vector<uint8_t> p = {type, 3};
        p.insert(p.end(), body.begin(), body.end());
        p.push_back(0);
        p.push_back(0);  // crc is checked by the decoder, not the parser
        return p;
    };
    Command c;
    auto parse = [&](std::vector<uint8_t> p) { return CommandParser::parse(p.data(), (uint8_t)p.size(), c); };
    CHECK(parse(payload(CMD_SET_STREAM, {7, 200, 0, 100, 0})) == RESULT_OK);
    CHECK(parse(payload(CMD_SET_STREAM, {8, 0, 0, 0, 0})) == RESULT_BAD_VALUE);     // unknown bit
    CHECK(parse(payload(CMD_SET_STREAM, {1, 0, 0, 0, 0})) == RESULT_BAD_VALUE);     // raw on at 0 Hz
    CHECK(parse(payload(CMD_SET_STREAM, {0, 25, 0, 0, 0})) == RESULT_BAD_VALUE);    // raw off at 25 Hz
    CHECK(parse(payload(CMD_SET_STREAM, {3, 144, 1, 1, 0})) == RESULT_BAD_VALUE);   // 400 Hz
    CHECK(parse(payload(CMD_SET_STREAM, {2, 0, 0, 1, 0})) == RESULT_OK);            // orientation 1 Hz
    CHECK(parse(payload(CMD_SET_TAP, {0, 1, 0, 0, 7})) == RESULT_BAD_VALUE);
    CHECK(parse(payload(CMD_SET_TAP, {1, 1, 0, 0, 0x17})) == RESULT_BAD_VALUE);
    CHECK(parse(payload(CMD_SET_TAP, {1, 1, 0, 0, 0x0F})) == RESULT_OK);
    CHECK(parse(payload(CMD_SET_FREE_FALL, {1, 0})) == RESULT_BAD_VALUE);
    CHECK(parse(payload(CMD_SET_FILTER, {0xD1, 0x07})) == RESULT_BAD_VALUE);  // 2001
    CHECK(parse(payload(CMD_SET_FILTER, {0xD0, 0x07})) == RESULT_OK);         // 2000
    CHECK(parse(payload(CMD_CALIBRATION_STEP, {4, 1})) == RESULT_BAD_VALUE);
    CHECK(parse(payload(CMD_CALIBRATION_STEP, {3, 2})) == RESULT_BAD_VALUE);
    CHECK(parse(payload(CMD_IDENTIFY, {61})) == RESULT_BAD_VALUE);
    CHECK(parse(payload(CMD_IDENTIFY, {0})) == RESULT_BAD_VALUE);
    CHECK(parse(payload(CMD_REBOOT, {0x07, 0xB0})) == RESULT_OK);
    CHECK(parse(payload(CMD_REBOOT, {0xB0, 0x07})) == RESULT_BAD_VALUE);
    CHECK(parse(payload(CMD_GET_STATUS, {1})) == RESULT_BAD_LENGTH);
    CHECK(parse(payload(0x02, {})) == RESULT_UNKNOWN_COMMAND);  // a device type sent as a command
    CHECK(parse(payload(0x51, {})) == RESULT_UNKNOWN_COMMAND);  // reserved (spec §5), not a command yet
    CHECK(parse(payload(CMD_SET_BAUD, {0x00, 0x84, 0x03, 0x00})) == RESULT_BAD_VALUE);  // 230400: not exact
    CHECK(parse(payload(CMD_SET_BAUD, {0x20, 0xA1, 0x07, 0x00})) == RESULT_OK);
    CHECK(c.set_baud.baud == 500000);
    CHECK(parse(payload(CMD_SET_BOARD, {2})) == RESULT_OK);
    CHECK(c.set_board.board_profile == 2);
    CHECK(parse(payload(CMD_SET_BOARD, {3})) == RESULT_BAD_VALUE);
}

TEST_CASE("SET_CALIBRATION values outside the spec's ranges are bad_value") {
    Calibration ok;
    ok.setDefaults();
    Command c;
    auto parseCal = [&](const Calibration& cal) {
        std::vector<uint8_t> p = {CMD_SET_CALIBRATION, 1};
        const uint8_t* b = (const uint8_t*)&cal;
        p.insert(p.end(), b, b + CALIBRATION_BLOCK_LEN);
        uint16_t crc = crc16(p.data(), p.size());
        p.push_back((uint8_t)crc);
        p.push_back((uint8_t)(crc >> 8));
        return CommandParser::parse(p.data(), (uint8_t)p.size(), c);
    };
    CHECK(parseCal(ok) == RESULT_OK);
    Calibration bad = ok;
    bad.accel_scale[1] = 0;  // scale 0
    CHECK(parseCal(bad) == RESULT_BAD_VALUE);
    bad = ok;
    bad.accel_scale[2] = 8191;  // just under 0.5
    CHECK(parseCal(bad) == RESULT_BAD_VALUE);
    bad = ok;
    bad.gyro_bias[0] = 1001;
    CHECK(parseCal(bad) == RESULT_BAD_VALUE);
    bad = ok;
    bad.accel_offset[2] = -513;
    CHECK(parseCal(bad) == RESULT_BAD_VALUE);
    bad = ok;
    bad.mag_offset[1] = 2049;
    CHECK(parseCal(bad) == RESULT_BAD_VALUE);
    bad = ok;  // a singular soft-iron matrix: two equal rows
    bad.mag_soft_iron[3] = 16384;
    bad.mag_soft_iron[4] = 0;
    CHECK(parseCal(bad) == RESULT_BAD_VALUE);
    bad = ok;  // near-singular: determinant 1/32
    bad.mag_soft_iron[8] = 16384 / 32;
    CHECK(parseCal(bad) == RESULT_BAD_VALUE);
    Calibration swap = ok;  // a reflection (x and y swapped) is invertible
    swap.mag_soft_iron[0] = swap.mag_soft_iron[4] = 0;
    swap.mag_soft_iron[1] = swap.mag_soft_iron[3] = 16384;
    CHECK(parseCal(swap) == RESULT_OK);
    // the limits themselves are valid
    Calibration edge = ok;
    edge.gyro_bias[0] = -1000;
    edge.accel_offset[0] = 512;
    edge.accel_scale[0] = 8192;
    edge.accel_scale[1] = 32767;
    edge.mag_offset[2] = -2048;
    CHECK(parseCal(edge) == RESULT_OK);
    // an EEPROM image with such values is refused at boot like one with a bad CRC
    uint8_t img[CALIBRATION_EEPROM_LEN];
    bad = ok;
    bad.accel_scale[0] = 0;
    writeCalibrationImage(bad, img);  // version and CRC right
    Calibration out;
    out.setDefaults();
    CHECK_FALSE(readCalibrationImage(img, out));
    CHECK(out.accelIsDefault());
}
