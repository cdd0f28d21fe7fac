// Drivers against register-map fakes, and SphereDevice end to end: streams, commands, faults, taps.
#include <algorithm>
#include <cmath>

#include "doctest_include.h"

#include "bytes.h"
#include "fakes.h"
#include "test_paths.h"
#include "vectors.h"

using namespace sphere;

namespace {

struct Rig {
    FakeBus bus;
    FakeHal hal;
    SphereDevice dev{bus, hal};
    Rig() {
        bus.setAccel(0, 0, 256);
        bus.setGyro(5, -7, 1);
        bus.setMag(300, 0, -400);
    }
    void run(int ticks) {
        for (int i = 0; i < ticks; ++i) {
            hal.now += 5000;
            if (i % 3 == 0) bus.setMag(300, 0, -400);  // 75 Hz: a new sample every ~2.7 ticks
            dev.tick();
        }
    }
    void send(const std::vector<uint8_t>& wire) {
        for (uint8_t b : wire) dev.receive(b);
    }
};

int count(const std::vector<std::vector<uint8_t>>& f, uint8_t type) {
    int n = 0;
    for (auto& p : f) n += p[0] == type;
    return n;
}

const std::vector<uint8_t>* first(const std::vector<std::vector<uint8_t>>& f, uint8_t type) {
    for (auto& p : f)
        if (p[0] == type) return &p;
    return nullptr;
}

}  // namespace

TEST_CASE("register decoding: ADXL345 little-endian, ITG-3200 big-endian, HMC5883L X Z Y") {
    int16_t o[3];
    const uint8_t a[6] = {0xFD, 0xFF, 0x0C, 0x00, 0x00, 0x01};
    Adxl345::decode(a, o);
    CHECK(o[0] == -3);
    CHECK(o[1] == 12);
    CHECK(o[2] == 256);
    const uint8_t g[6] = {0x80, 0x00, 0x7F, 0xFF, 0x00, 0x05};
    Itg3200::decode(g, o);
    CHECK(o[0] == -32768);
    CHECK(o[1] == 32767);
    CHECK(o[2] == 5);
    const uint8_t m[6] = {0x00, 0xD2, 0xFE, 0x84, 0xFF, 0xD3};  // X=210, Z=−380, Y=−45
    Hmc5883l::decode(m, o);
    CHECK(o[0] == 210);
    CHECK(o[1] == -45);
    CHECK(o[2] == -380);
    const uint8_t ov[6] = {0xF0, 0x00, 0x00, 0x10, 0x00, 0x20};
    Hmc5883l::decode(ov, o);
    CHECK(o[0] == (int)Hmc5883l::OVERFLOW);
    CHECK(Itg3200::whoamiValid(0x68));
    CHECK(Itg3200::whoamiValid(0x69));
    CHECK_FALSE(Itg3200::whoamiValid(0x00));
}

TEST_CASE("drivers configure the chips as documented") {
    FakeBus bus;
    Adxl345 adxl(bus);
    Itg3200 itg(bus);
    Hmc5883l hmc(bus);
    REQUIRE(adxl.begin(Adxl345::DEFAULT_TAP, Adxl345::DEFAULT_FREE_FALL));
    CHECK(bus.adxl.regs[0x31] == 0x0B);  // FULL_RES, ±16 g
    CHECK(bus.adxl.regs[0x2C] == 0x0C);  // 400 Hz (200 Hz bandwidth)
    CHECK(bus.adxl.regs[0x2D] == 0x08);  // measure
    CHECK(bus.adxl.regs[0x2E] == 0x64);  // single, double tap, free fall
    CHECK(bus.adxl.regs[0x2F] == 0x9B);  // those on INT1
    CHECK(bus.adxl.regs[0x1D] == 48);
    CHECK(bus.adxl.regs[0x2A] == 7);
    CHECK(bus.adxl.writes.back().first == 0x2D);  // measurement starts last
    REQUIRE(itg.begin());
    CHECK(itg.address() == 0x68);
    CHECK(bus.itg.regs[0x15] == 0);     // every 1 kHz internal sample: the register is at most 1 ms old when read
    CHECK(bus.itg.regs[0x16] == 0x1A);  // FS_SEL 3, DLPF 98 Hz (at the 100 Hz Nyquist limit of the 200 Hz read)
    CHECK(bus.itg.regs[0x3E] == 0x01);
    REQUIRE(hmc.begin());
    CHECK(bus.hmc.regs[0x00] == 0x18);  // one sample per measurement
    CHECK(bus.hmc.regs[0x01] == 0x20);  // gain 1
    CHECK(bus.hmc.regs[0x02] == 0x01);  // single measurement: the first conversion triggered

    // ITG-3200 with AD0 high answers at 0x69
    bus.itg.addr = 0x69;
    Itg3200 itg2(bus);
    REQUIRE(itg2.begin());
    CHECK(itg2.address() == 0x69);
    // a wrong ID is not accepted
    bus.adxl.regs[0] = 0x00;
    Adxl345 bad(bus);
    CHECK_FALSE(bad.begin(Adxl345::DEFAULT_TAP, Adxl345::DEFAULT_FREE_FALL));
    // HMC5883L single measurement: the conversion triggered by begin() is read TRIGGER_TICKS periods
    // later, when RDY says it is new, and the next one is triggered
    int16_t m[3] = {1, 2, 3};
    bool fresh = true;
    REQUIRE(hmc.poll(m, fresh));  // converting
    CHECK_FALSE(fresh);
    CHECK(m[0] == 1);
    bus.setMag(-10, 20, -30);     // the conversion ends
    bus.hmc.writes.clear();
    REQUIRE(hmc.poll(m, fresh));
    CHECK(fresh);
    CHECK(m[0] == -10);
    CHECK(m[1] == 20);
    CHECK(m[2] == -30);
    REQUIRE(bus.hmc.writes.size() == 1);
    CHECK(bus.hmc.writes[0] == std::make_pair((uint8_t)0x02, (uint8_t)0x01));  // next conversion
    // RDY still clear when the data are due: nothing is read as fresh, and after TIMEOUT_TICKS the
    // chip is triggered again (a lost trigger does not stop the magnetometer)
    bus.hmc.writes.clear();
    int fresh_count = 0;
    for (int i = 0; i < Hmc5883l::TIMEOUT_TICKS; ++i) {
        REQUIRE(hmc.poll(m, fresh));
        fresh_count += fresh;
    }
    CHECK(fresh_count == 0);
    CHECK(bus.hmc.writes.size() == 1);
    CHECK(m[0] == -10);
}

TEST_CASE("calibration maths and the EEPROM image") {
    Calibration c;
    c.setDefaults();
    int16_t raw[3] = {100, -200, 300}, o[3];
    applyAccel(c, raw, o);
    CHECK(o[0] == 100);
    CHECK(o[2] == 300);
    applyMag(c, raw, o);
    CHECK(o[1] == -200);
    c.gyro_bias[0] = 10;
    c.accel_offset[1] = -8;
    c.accel_scale[1] = 8192;  // 0.5
    c.mag_offset[2] = 50;
    c.mag_soft_iron[0] = 0;
    c.mag_soft_iron[1] = 16384;  // x' = y
    c.mag_soft_iron[3] = 16384;  // y' = x
    c.mag_soft_iron[4] = 0;
    applyGyro(c, raw, o);
    CHECK(o[0] == 90);
    applyAccel(c, raw, o);
    CHECK(o[1] == -96);  // (−200 + 8) · 0.5
    applyMag(c, raw, o);
    CHECK(o[0] == -200);
    CHECK(o[2] == 250);
    int16_t sat[3] = {-32768, 0, 0};
    c.gyro_bias[0] = 100;
    applyGyro(c, sat, o);
    CHECK(o[0] == -32768);  // saturates, no wrap

    uint8_t img[CALIBRATION_EEPROM_LEN];
    writeCalibrationImage(c, img);
    CHECK(img[0] == CALIBRATION_EEPROM_VERSION);
    Calibration d;
    d.setDefaults();
    REQUIRE(readCalibrationImage(img, d));
    CHECK(std::memcmp(&c, &d, sizeof c) == 0);
    for (size_t i = 0; i < sizeof img; ++i) {
        uint8_t bad[CALIBRATION_EEPROM_LEN];
        std::memcpy(bad, img, sizeof img);
        bad[i] ^= 0x10;
        Calibration e;
        e.setDefaults();
        CHECK_FALSE(readCalibrationImage(bad, e));
        CHECK(e.accelIsDefault());  // untouched
    }
    uint8_t erased[CALIBRATION_EEPROM_LEN];
    std::memset(erased, 0xFF, sizeof erased);
    CHECK_FALSE(readCalibrationImage(erased, d));
}

TEST_CASE("power-up: a 0x00, HELLO, gyro bias estimated while still, then the default streams") {
    Rig r;
    r.dev.begin();
    REQUIRE(!r.hal.wire.empty());
    CHECK(r.hal.wire[0] == 0x00);
    auto f = r.hal.frames();
    REQUIRE(f.size() == 1);
    CHECK(f[0][0] == PKT_HELLO);
    CHECK(f[0][1] == 0);  // seq 0 after power-up
    const uint8_t* h = f[0].data() + 2;
    CHECK(h[0] == 3);     // protocol version (spec: version 3)
    CHECK(h[4] == 7);     // sensors_found
    CHECK(h[5] == 0xE5);
    CHECK(h[6] == 0x69);
    CHECK(h[7] == 'H');
    CHECK(getU16(h + 10) == 200);
    CHECK(h[13] == 7);
    CHECK(getU16(h + 14) == 200);
    CHECK(getU16(h + 16) == 100);
    CHECK(h[18] == CAL_EEPROM_INVALID);
    CHECK(h[19] == RESET_POWER_ON);     // reset_cause
    CHECK(h[20] == MAG_CHIP_HMC5883L);  // mag_chip
    CHECK(h[21] == BOARD_ALIGNED);      // board_profile (EEPROM erased)
    CHECK(h[12] == 100);                // mag_rate_hz: a conversion every second period

    r.run(200);
    f = r.hal.frames();
    CHECK(count(f, PKT_RAW_SAMPLE) == 200);
    CHECK(count(f, PKT_ORIENTATION) == 100);
    CHECK(count(f, PKT_STATUS) == 1);
    for (size_t i = 0; i < f.size(); ++i) CHECK(f[i][1] == (uint8_t)(i + 1));  // no gaps
    CHECK(f[0][0] == PKT_RAW_SAMPLE);  // the sample first within a period: it is sent before the MARG update
    CHECK(f[1][0] == PKT_ORIENTATION);
    r.run(10);  // the first window restarts once when the magnetometer's first sample arrives
    f = r.hal.frames();
    CHECK((int)r.dev.calibration().gyro_bias[0] == 5);
    CHECK((int)r.dev.calibration().gyro_bias[1] == -7);
    CHECK((int)r.dev.calibration().gyro_bias[2] == 1);
    CHECK(r.dev.calibrationState() == (CAL_EEPROM_INVALID | CAL_GYRO_BIAS_VALID | CAL_GYRO_BIAS_ESTIMATED));
    CHECK(r.hal.pin_pulses == 210);
    CHECK(r.hal.pin_high == 0);
    const auto* raw = first(f, PKT_RAW_SAMPLE);
    REQUIRE(raw);
    CHECK(getI16(raw->data() + 2 + 5 + 4) == 256);  // accel z
    CHECK(getI16(raw->data() + 2 + 11) == 5);       // gyro x, uncalibrated
    CHECK(getI16(raw->data() + 2 + 17) == 300);     // mag x
    CHECK(getI16(raw->data() + 2 + 19) == 0);       // mag y
    CHECK(getI16(raw->data() + 2 + 21) == -400);    // mag z
}

TEST_CASE("orientation: level and facing magnetic north converges to identity") {
    Rig r;
    r.bus.setGyro(0, 0, 0);
    r.dev.begin();
    r.run(800);
    auto f = r.hal.frames();
    const std::vector<uint8_t>* last = nullptr;
    for (auto& p : f)
        if (p[0] == PKT_ORIENTATION) last = &p;
    REQUIRE(last);
    const uint8_t* b = last->data() + 2;
    CHECK((b[4] & ORI_MAG_USED));
    CHECK_FALSE((b[4] & ORI_CONVERGING));
    CHECK(std::abs(getI16(b + 5) - 16384) < 20);
    for (int i = 1; i < 4; ++i) CHECK(std::abs(getI16(b + 5 + 2 * i)) < 100);
}

TEST_CASE("every host command vector gets exactly one REPLY with the listed result") {
    auto vectors = loadVectors(repoPath("protocol/vectors/frames.txt"));
    int n = 0;
    for (const auto& v : vectors) {
        if (v.get("direction") != "host") continue;
        CAPTURE(v.name);
        Rig r;
        if (v.name == "cmd_load_calibration") {  // a valid calibration in EEPROM to load
            Calibration c;
            c.setDefaults();
            writeCalibrationImage(c, r.hal.eeprom);
        }
        r.dev.begin();
        r.hal.frames();
        r.send(v.wire);
        auto f = r.hal.frames();
        REQUIRE(count(f, PKT_REPLY) == 1);
        const auto* rep = first(f, PKT_REPLY);
        CHECK((*rep)[2] == parseInts(v.get("seq")).at(0));
        uint8_t expect = v.name == "cmd_set_stream_bad_rate" || v.name == "cmd_set_baud_bad_rate" ? RESULT_BAD_VALUE
                         : v.get("outcome") == "bad_length" ? RESULT_BAD_LENGTH
                         : v.get("outcome") == "unknown_type" ? RESULT_UNKNOWN_COMMAND
                                                              : RESULT_OK;
        CHECK((*rep)[4] == expect);
        if (v.name == "cmd_get_hello") CHECK(count(f, PKT_HELLO) == 1);
        if (v.name == "cmd_get_status") CHECK(count(f, PKT_STATUS) == 1);
        if (v.name == "cmd_get_calibration") CHECK(rep->size() == 4 + 46);
        if (v.name == "cmd_identify") CHECK(r.hal.identify_s == 5);
        if (v.name == "cmd_reboot") CHECK(r.hal.reboots == 1);
        if (v.name == "cmd_set_tap") CHECK(r.bus.adxl.regs[0x23] == 240);
        if (v.name == "cmd_set_free_fall") CHECK(r.bus.adxl.regs[0x29] == 30);
        if (v.name == "cmd_save_calibration") CHECK(r.hal.eeprom[0] == CALIBRATION_EEPROM_VERSION);
        if (v.name == "cmd_set_board") CHECK(r.dev.boardProfile() == BOARD_SEN10724);
        if (v.name == "cmd_get_settings") CHECK(rep->size() == 4 + 3 + SETTINGS_BLOCK_LEN + 1);
        if (v.name == "cmd_save_settings") CHECK(r.hal.eeprom[SETTINGS_EEPROM_ADDR] == SETTINGS_EEPROM_VERSION);
        if (v.name == "cmd_clear_settings") CHECK(r.dev.settingsState() == SETTINGS_NONE_SAVED);
        if (v.name == "cmd_set_baud") CHECK((r.hal.baud == 1000000 && r.dev.linkQuiet()));
        if (v.name == "cmd_set_baud_bad_rate") CHECK((r.hal.baud_switches == 0 && !r.dev.linkQuiet()));
        if (v.name == "cmd_echo") CHECK(rep->size() == 4 + 3 + 4);
        ++n;
    }
    CHECK(n == 24);
}

TEST_CASE("SET_BAUD: REPLY at the old rate, silence until the host's frame at the new one, fall-backs") {
    Rig r;
    r.dev.begin();
    r.run(10);
    r.hal.frames();
    // confirmed: the REPLY, then nothing (no sequence number used) until the ECHO, whose REPLY carries the time
    r.send(frameOf(CMD_SET_BAUD, 1, {0x40, 0x42, 0x0F, 0x00}));  // 1,000,000
    auto f = r.hal.frames();
    REQUIRE(f.size() == 1);
    CHECK((f[0][0] == PKT_REPLY && f[0][4] == RESULT_OK));
    uint8_t seq_reply = f[0][1];
    CHECK((r.hal.baud == 1000000 && r.hal.baud_switches == 1 && r.dev.linkQuiet()));
    r.run(50);
    CHECK(r.hal.frames().empty());
    r.hal.now = 4000000000u;
    r.send(frameOf(CMD_ECHO, 2, {}));
    f = r.hal.frames();
    REQUIRE(f.size() == 1);
    CHECK((uint8_t)(f[0][1] - seq_reply) == 1);  // no gap: the silent periods took no numbers
    CHECK(getU32(&f[0][5]) >= 4000000000u);
    CHECK(!r.dev.linkQuiet());
    // renewed every 0.5 s (100 periods): the rate holds; the stream goes on
    for (int i = 0; i < 6; ++i) {
        r.run(100);
        r.send(frameOf(CMD_ECHO, (uint8_t)(3 + i), {}));
    }
    CHECK((r.hal.baud == 1000000 && r.hal.baud_switches == 1));
    CHECK(count(r.hal.frames(), PKT_RAW_SAMPLE) == 600);
    // the host goes away: 1.5 s without an intact frame, back to 115200, a 0x00, the stream resumes
    r.run(299);
    CHECK(r.hal.baud == 1000000);
    r.run(1);
    CHECK((r.hal.baud == 115200 && r.hal.baud_switches == 2));
    r.hal.frames();
    // a host that never confirms: 1 s of silence, then 115200 again
    r.send(frameOf(CMD_SET_BAUD, 20, {0x90, 0xD0, 0x03, 0x00}));  // 250,000
    CHECK(r.hal.baud == 250000);
    r.hal.frames();
    r.run(199);
    CHECK(r.hal.frames().empty());
    r.run(1);
    CHECK((r.hal.baud == 115200 && !r.dev.linkQuiet()));
    r.run(2);
    f = r.hal.frames();
    CHECK(count(f, PKT_RAW_SAMPLE) >= 2);
    // the rate in use: OK and nothing changes
    int switches = r.hal.baud_switches;
    r.send(frameOf(CMD_SET_BAUD, 21, {0x00, 0xC2, 0x01, 0x00}));  // 115200
    CHECK((r.hal.baud_switches == switches && !r.dev.linkQuiet()));
}

TEST_CASE("SET_STREAM changes the streams; an invalid one changes nothing") {
    Rig r;
    r.dev.begin();
    r.run(10);
    r.hal.frames();
    r.send(frameOf(CMD_SET_STREAM, 1, {2, 0, 0, 25, 0}));  // orientation 25 Hz only
    r.run(200);
    auto f = r.hal.frames();
    CHECK(count(f, PKT_REPLY) == 1);
    CHECK(count(f, PKT_RAW_SAMPLE) == 0);
    CHECK(count(f, PKT_STATUS) == 0);
    CHECK(count(f, PKT_ORIENTATION) == 25);
    r.send(frameOf(CMD_SET_STREAM, 2, {1, 30, 0, 0, 0}));  // 30 Hz: bad_value
    r.run(200);
    f = r.hal.frames();
    CHECK((*first(f, PKT_REPLY))[4] == RESULT_BAD_VALUE);
    CHECK(count(f, PKT_ORIENTATION) == 25);
    CHECK(r.dev.streamMode() == STREAM_ORIENTATION);
}

TEST_CASE("calibration commands: set, get, save, load, reset; a broken EEPROM is refused") {
    Rig r;
    r.dev.begin();
    r.hal.frames();
    std::vector<uint8_t> block;
    for (int i = 0; i < 21; ++i) {
        int16_t v = (int16_t)(i < 6 ? i - 3 : i < 9 ? 16000 + i : i < 12 ? -i : (i % 4 == 0 ? 16384 : i));
        block.push_back((uint8_t)v);
        block.push_back((uint8_t)((uint16_t)v >> 8));
    }
    r.send(frameOf(CMD_SET_CALIBRATION, 1, block));
    r.send(frameOf(CMD_GET_CALIBRATION, 2, {}));
    auto f = r.hal.frames();
    REQUIRE(f.size() == 2);
    CHECK(f[0][4] == RESULT_OK);
    REQUIRE(f[1].size() == 4 + 46);
    CHECK(std::vector<uint8_t>(f[1].begin() + 5, f[1].begin() + 5 + 42) == block);
    uint8_t state = f[1][5 + 42];
    CHECK((state & (CAL_GYRO_BIAS_VALID | CAL_ACCEL_CALIBRATED | CAL_MAG_CALIBRATED)) ==
          (CAL_GYRO_BIAS_VALID | CAL_ACCEL_CALIBRATED | CAL_MAG_CALIBRATED));
    r.send(frameOf(CMD_SAVE_CALIBRATION, 3, {}));
    r.send(frameOf(CMD_RESET_CALIBRATION, 4, {}));
    CHECK(r.dev.calibration().accelIsDefault());
    r.send(frameOf(CMD_LOAD_CALIBRATION, 5, {}));
    f = r.hal.frames();
    for (auto& p : f) CHECK(p[4] == RESULT_OK);
    CHECK((int)r.dev.calibration().accel_scale[0] == 16006);
    CHECK((r.dev.calibrationState() & CAL_FROM_EEPROM));
    // a new power-up finds it in EEPROM
    Rig r2;
    std::memcpy(r2.hal.eeprom, r.hal.eeprom, 64);
    r2.dev.begin();
    CHECK((int)r2.dev.calibration().accel_scale[0] == 16006);
    CHECK((r2.dev.calibrationState() & CAL_FROM_EEPROM));
    CHECK_FALSE((r2.dev.calibrationState() & CAL_EEPROM_INVALID));
    // damaged EEPROM: load refused, calibration in use unchanged
    r.hal.eeprom[10] ^= 1;
    r.send(frameOf(CMD_RESET_CALIBRATION, 6, {}));
    r.send(frameOf(CMD_LOAD_CALIBRATION, 7, {}));
    f = r.hal.frames();
    CHECK(f.back()[4] == RESULT_STORAGE_ERROR);
    CHECK(r.dev.calibration().accelIsDefault());
    // a failing EEPROM write
    r.hal.eeprom_fails = true;
    r.send(frameOf(CMD_SAVE_CALIBRATION, 8, {}));
    CHECK(r.hal.frames().back()[4] == RESULT_STORAGE_ERROR);
}

TEST_CASE("settings: read back, saved, applied at the next power-up; a corrupt block is refused whole") {
    Rig r;
    r.dev.begin();
    CHECK(r.dev.settingsState() == SETTINGS_NONE_SAVED);  // an erased EEPROM
    r.hal.frames();
    r.send(frameOf(CMD_SET_STREAM, 1, {3, 100, 0, 50, 0}));
    r.send(frameOf(CMD_SET_TAP, 2, {40, 32, 0, 0, 1}));
    r.send(frameOf(CMD_SET_FREE_FALL, 3, {8, 40}));
    r.send(frameOf(CMD_SET_FILTER, 4, {60, 0}));
    r.send(frameOf(CMD_GET_SETTINGS, 5, {}));
    auto f = r.hal.frames();
    REQUIRE(f.size() == 5);
    const std::vector<uint8_t> expect = {3, 100, 0, 50, 0, 40, 32, 0, 0, 1, 8, 40, 60, 0};
    REQUIRE(f[4].size() == 4 + 3 + SETTINGS_BLOCK_LEN + 1);
    CHECK(std::vector<uint8_t>(f[4].begin() + 5, f[4].begin() + 5 + SETTINGS_BLOCK_LEN) == expect);
    CHECK(f[4][5 + SETTINGS_BLOCK_LEN] == SETTINGS_NONE_SAVED);  // changed, nothing saved yet
    r.send(frameOf(CMD_SAVE_SETTINGS, 6, {}));
    CHECK(r.hal.frames().back()[4] == RESULT_OK);
    CHECK(r.dev.settingsState() == SETTINGS_SAVED);
    // a new power-up: the saved settings are in use, in the chip's registers too
    Rig r2;
    std::memcpy(r2.hal.eeprom, r.hal.eeprom, sizeof r.hal.eeprom);
    r2.dev.begin();
    CHECK(r2.dev.settingsState() == SETTINGS_SAVED);
    uint8_t block[SETTINGS_BLOCK_LEN];
    r2.dev.settingsBlock(block);
    CHECK(std::vector<uint8_t>(block, block + SETTINGS_BLOCK_LEN) == expect);
    CHECK(r2.bus.adxl.regs[0x1D] == 40);  // THRESH_TAP
    CHECK(r2.bus.adxl.regs[0x2A] == 1);   // TAP_AXES: z
    CHECK(r2.bus.adxl.regs[0x28] == 8);   // THRESH_FF
    CHECK(r2.dev.streamMode() == 3);
    r2.send(frameOf(CMD_SET_FILTER, 1, {41, 0}));
    CHECK(r2.dev.settingsState() == 0);  // in use differs from saved
    // one flipped bit: nothing of the block is used, the defaults are, and GET_SETTINGS says so
    Rig r3;
    std::memcpy(r3.hal.eeprom, r.hal.eeprom, sizeof r.hal.eeprom);
    r3.hal.eeprom[SETTINGS_EEPROM_ADDR + 3] ^= 4;
    r3.dev.begin();
    CHECK(r3.dev.settingsState() == (SETTINGS_EEPROM_INVALID | SETTINGS_NONE_SAVED));
    CHECK(r3.dev.streamMode() == (STREAM_RAW | STREAM_ORIENTATION | STREAM_STATUS));
    CHECK(r3.bus.adxl.regs[0x1D] == Adxl345::DEFAULT_TAP.thresh_tap);
    // a block with a good CRC but a value no command accepts (raw rate 30 Hz): refused whole as well
    uint8_t bad[SETTINGS_BLOCK_LEN];
    std::memcpy(bad, expect.data(), SETTINGS_BLOCK_LEN);
    bad[1] = 30;
    Rig r4;
    writeSettingsImage(bad, r4.hal.eeprom + SETTINGS_EEPROM_ADDR);
    r4.dev.begin();
    CHECK(r4.dev.settingsState() == (SETTINGS_EEPROM_INVALID | SETTINGS_NONE_SAVED));
    CHECK(r4.bus.adxl.regs[0x1D] == Adxl345::DEFAULT_TAP.thresh_tap);
    // CLEAR_SETTINGS: the next power-up uses the defaults; a failing write is storage_error
    r.send(frameOf(CMD_CLEAR_SETTINGS, 7, {}));
    CHECK(r.hal.frames().back()[4] == RESULT_OK);
    Rig r5;
    std::memcpy(r5.hal.eeprom, r.hal.eeprom, sizeof r.hal.eeprom);
    r5.dev.begin();
    CHECK(r5.dev.settingsState() == SETTINGS_NONE_SAVED);
    CHECK(r5.dev.streamMode() == (STREAM_RAW | STREAM_ORIENTATION | STREAM_STATUS));
    r.hal.eeprom_fails = true;
    r.send(frameOf(CMD_SAVE_SETTINGS, 8, {}));
    CHECK(r.hal.frames().back()[4] == RESULT_STORAGE_ERROR);
}

TEST_CASE("a calibration the host sets or loads is not overwritten by a gyro bias estimate still running") {
    Rig r;
    r.dev.begin();  // the power-up estimate runs (gyro 5, -7, 1)
    r.run(50);
    std::vector<uint8_t> block;
    for (int i = 0; i < 21; ++i) {
        int16_t v = (int16_t)(i < 3 ? -30 + i : i < 6 ? 0 : i < 9 ? 16384 : i < 12 ? 0 : (i % 4 == 0 ? 16384 : 0));
        block.push_back((uint8_t)v);
        block.push_back((uint8_t)((uint16_t)v >> 8));
    }
    r.send(frameOf(CMD_SET_CALIBRATION, 1, block));
    r.run(175);  // past where the power-up window would have ended, before a tracking window ends
    CHECK((int)r.dev.calibration().gyro_bias[0] == -30);
    CHECK((int)r.dev.calibration().gyro_bias[2] == -28);
    CHECK_FALSE((r.dev.calibrationState() & CAL_GYRO_BIAS_ESTIMATED));
    // still for longer: tracking moves the host's bias by at most TRACK_STEP_LSB per window
    r.run(120);
    CHECK((int)r.dev.calibration().gyro_bias[0] == -30 + SphereDevice::TRACK_STEP_LSB);
    CHECK((r.dev.calibrationState() & CAL_GYRO_BIAS_ESTIMATED));
    // the same for a CALIBRATION_STEP gyro_bias under way when the stored block is loaded
    r.send(frameOf(CMD_SAVE_CALIBRATION, 2, {}));
    r.send(frameOf(CMD_CALIBRATION_STEP, 3, {1, 1}));
    r.run(100);
    r.send(frameOf(CMD_LOAD_CALIBRATION, 4, {}));
    r.run(SphereDevice::STEP_BIAS_SAMPLES - 100 + 50);  // past where the step would have ended
    auto f = r.hal.frames();
    for (auto& p : f)
        if (p[0] == PKT_REPLY) CHECK(p[4] == RESULT_OK);
    // as saved, and tracking since (one window: at most a step); the step's estimate would have made it 5
    CHECK(std::abs(r.dev.calibration().gyro_bias[0] - (-30 + SphereDevice::TRACK_STEP_LSB)) <= (int)SphereDevice::TRACK_STEP_LSB);
    r.send(frameOf(CMD_GET_STATUS, 5, {}));
    f = r.hal.frames();
    REQUIRE(f.back()[0] == PKT_STATUS);
    CHECK(f.back()[2 + 20] == 0);  // the step ended
}

TEST_CASE("calibration steps: busy, stop, gyro bias over 2 s") {
    Rig r;
    r.dev.begin();
    r.run(250);
    r.hal.frames();
    r.send(frameOf(CMD_CALIBRATION_STEP, 1, {3, 1}));  // mag
    r.send(frameOf(CMD_CALIBRATION_STEP, 2, {1, 1}));  // gyro while mag runs: busy
    r.send(frameOf(CMD_CALIBRATION_STEP, 3, {3, 0}));  // stop
    r.bus.setGyro(20, 21, 22);
    r.send(frameOf(CMD_CALIBRATION_STEP, 4, {1, 1}));
    auto f = r.hal.frames();
    REQUIRE(f.size() == 4);
    CHECK(f[0][4] == RESULT_OK);
    CHECK(f[1][4] == RESULT_BUSY);
    CHECK(f[2][4] == RESULT_OK);
    CHECK(f[3][4] == RESULT_OK);
    r.run(401);
    CHECK((int)r.dev.calibration().gyro_bias[0] == 20);
    CHECK((int)r.dev.calibration().gyro_bias[2] == 22);
    r.send(frameOf(CMD_GET_STATUS, 5, {}));
    f = r.hal.frames();
    REQUIRE(f.back()[0] == PKT_STATUS);
    CHECK(f.back()[2 + 20] == 0);  // calibration_step back to none
}

TEST_CASE("faults: a sensor that stops answering is marked, the rest keeps streaming, and it comes back") {
    Rig r;
    r.dev.begin();
    r.run(500);
    r.hal.frames();
    r.bus.hmc.present = false;
    r.run(300);
    auto f = r.hal.frames();
    CHECK(count(f, PKT_RAW_SAMPLE) == 300);
    CHECK_FALSE((r.dev.sensorsOk() & SENSOR_HMC5883L));
    CHECK(r.dev.status().i2c_errors[2] >= 1);
    const std::vector<uint8_t>* last_ori = nullptr;
    for (auto& p : f)
        if (p[0] == PKT_ORIENTATION) last_ori = &p;
    REQUIRE(last_ori);
    CHECK(((*last_ori)[2 + 4] & ORI_MAG_USED) == 0);  // gravity only
    const std::vector<uint8_t>* last_raw = nullptr;
    for (auto& p : f)
        if (p[0] == PKT_RAW_SAMPLE) last_raw = &p;
    CHECK(((*last_raw)[2 + 4] & RAW_MAG_OK) == 0);
    CHECK(getI16(last_raw->data() + 2 + 17) == 0);
    r.bus.hmc.present = true;
    r.run(250);
    CHECK((r.dev.sensorsOk() & SENSOR_HMC5883L));
    f = r.hal.frames();
    const auto& lr = f[f.size() - 2][0] == PKT_RAW_SAMPLE ? f[f.size() - 2] : f.back();
    CHECK((lr[2 + 4] & RAW_MAG_OK));
    // the accelerometer gone too: still streaming, gyro only
    r.bus.adxl.present = false;
    r.bus.hmc.present = false;
    r.run(10);
    f = r.hal.frames();
    CHECK(count(f, PKT_RAW_SAMPLE) == 10);
    bool rej = (f.back()[2 + 4] & ORI_ACCEL_REJECTED) || (f[f.size() - 2][2 + 4] & ORI_ACCEL_REJECTED);
    CHECK(rej);
}

TEST_CASE("a tap: the accelerometer is ignored during the spike and the EVENT carries the spike's sign") {
    Rig r;
    r.dev.begin();
    r.run(500);
    r.hal.frames();
    // a spike on z: 256 → −600 → 900 → 256 (struck from above: first negative)
    int16_t z[] = {-600, 900, 256};
    for (int16_t v : z) {
        r.bus.setAccel(0, 0, v);
        r.run(1);
    }
    CHECK(r.dev.tapActive());
    r.bus.adxl.regs[0x30] = 0xC3;  // DATA_READY | SINGLE_TAP | watermark | overrun, as in the vector
    r.bus.adxl.regs[0x2B] = 0x01;  // first seen on z
    r.hal.interrupt = true;
    r.hal.interrupt_t = 777000;
    r.run(1);
    auto f = r.hal.frames();
    const auto* ev = first(f, PKT_EVENT);
    REQUIRE(ev);
    CHECK(getU32(ev->data() + 2) == 777000);
    CHECK((*ev)[2 + 4] == EVENT_SINGLE_TAP);
    CHECK((*ev)[2 + 5] == 0xC3);
    CHECK((*ev)[2 + 6] == 0x01);
    CHECK((int8_t)(*ev)[2 + 7] == -1);
    CHECK((r.bus.adxl.regs[0x30] & 0x40) == 0);  // INT_SOURCE was read (once) and cleared
    int tap_flags = 0, rejected = 0;
    for (auto& p : f) {
        if (p[0] == PKT_RAW_SAMPLE) tap_flags += (p[2 + 4] & RAW_TAP_ACTIVE) != 0;
        if (p[0] == PKT_ORIENTATION) rejected += (p[2 + 4] & ORI_ACCEL_REJECTED) != 0;
    }
    CHECK(tap_flags >= 3);
    CHECK(rejected >= 1);
    r.run(40);
    CHECK_FALSE(r.dev.tapActive());
    // free fall and double tap together
    r.bus.adxl.regs[0x30] = 0xA4;
    r.bus.adxl.regs[0x2B] = 0x04;
    r.hal.interrupt = true;
    r.hal.interrupt_t = r.hal.now;
    r.run(1);
    f = r.hal.frames();
    CHECK(count(f, PKT_EVENT) == 2);
    // the chip keeps raising FREE_FALL while the fall lasts: still one event per fall
    for (int i = 0; i < 30; ++i) {
        r.bus.adxl.regs[0x30] = 0x84;
        r.hal.interrupt = true;
        r.hal.interrupt_t = r.hal.now;
        r.run(1);
    }
    CHECK(count(r.hal.frames(), PKT_EVENT) == 0);
    r.run(60);  // 300 ms without it: the next one is a new fall
    r.bus.adxl.regs[0x30] = 0x84;
    r.hal.interrupt = true;
    r.hal.interrupt_t = r.hal.now;
    r.run(1);
    f = r.hal.frames();
    REQUIRE(count(f, PKT_EVENT) == 1);
    CHECK((*first(f, PKT_EVENT))[2 + 4] == EVENT_FREE_FALL);
}

TEST_CASE("damaged command frames are counted in rx_errors and not answered") {
    Rig r;
    r.dev.begin();
    r.hal.frames();
    auto good = frameOf(CMD_GET_STATUS, 9, {});
    auto bad = good;
    bad[2] ^= 0x01;
    r.send(bad);
    r.send({0x09, 0x02, 0x11, 0x00});  // COBS error
    r.send(good);
    auto f = r.hal.frames();
    REQUIRE(count(f, PKT_REPLY) == 1);
    const auto* st = first(f, PKT_STATUS);
    REQUIRE(st);
    CHECK(getU16(st->data() + 2 + 17) == 2);
}

TEST_CASE("a full transmit buffer drops frames, counts them and leaves a sequence gap") {
    Rig r;
    r.dev.begin();
    r.hal.frames();
    r.run(1);
    r.hal.tx_full = true;
    r.run(2);
    r.hal.tx_full = false;
    r.run(1);
    auto f = r.hal.frames();
    CHECK(r.dev.status().frames_dropped == 3);  // raw, orientation, raw
    REQUIRE(f.size() == 3);
    CHECK((uint8_t)(f[2][1] - f[1][1]) == 4);
}

TEST_CASE("gyro bias: a steady turn about the vertical is not mistaken for stillness") {
    GyroBiasEstimator e;
    int16_t g[3] = {0, 0, 144}, a[3] = {0, 0, 256};  // 10 °/s about z: gyro and accel constant
    e.start(200);
    int8_t r = 0;
    for (int i = 0; i < 200 && r == 0; ++i) {
        double h = 10.0 * i / 200 * M_PI / 180;  // the field turns with the heading
        int16_t m[3] = {(int16_t)std::lround(300 * std::cos(h)), (int16_t)std::lround(-300 * std::sin(h)), -400};
        r = e.update(g, a, m);
    }
    CHECK(r == -1);
    e.start(200);  // the same still: accepted, the mean is the bias
    int16_t m[3] = {300, 0, -400}, g2[3] = {3, -2, 7};
    for (int i = 0; i < 200 && r <= 0; ++i) r = e.update(g2, a, m);
    CHECK(r == 1);
    CHECK(e.bias()[2] == 7);
    e.start(10);  // without a magnetometer only gyro and accel count
    r = 0;
    for (int i = 0; i < 10 && r == 0; ++i) r = e.update(g, a, nullptr);
    CHECK(r == 1);
}

TEST_CASE("the start-up gain lasts until 400 samples had a usable accelerometer") {
    Rig r;
    r.bus.setGyro(0, 0, 0);
    r.bus.setAccel(0, 0, 500);  // 1.95 g: rejected
    r.dev.begin();
    r.run(600);
    auto f = r.hal.frames();
    const std::vector<uint8_t>* last = nullptr;
    for (auto& p : f)
        if (p[0] == PKT_ORIENTATION) last = &p;
    REQUIRE(last);
    CHECK(((*last)[2 + 4] & ORI_CONVERGING));
    CHECK(((*last)[2 + 4] & ORI_ACCEL_REJECTED));
    r.bus.setAccel(0, 0, 256);
    r.run(399);
    f = r.hal.frames();
    bool still_converging = (f.back()[2 + 4] & ORI_CONVERGING) || (f[f.size() - 2][2 + 4] & ORI_CONVERGING);
    CHECK(still_converging);
    r.run(2);
    f = r.hal.frames();
    for (auto& p : f)
        if (p[0] == PKT_ORIENTATION) CHECK_FALSE((p[2 + 4] & ORI_CONVERGING));
}

// The EEPROM as the ATmega328P has it: 3.4 ms a byte (EEPM 00, "EEPROM Mode Bits"). A block is written a byte a
// period from tick(), never waited for; the REPLY comes when it reads back as written.
TEST_CASE("SAVE_CALIBRATION writes a byte a period and answers when the block is stored; no period waits") {
    Rig r, ref;
    r.hal.eeprom_write_us = 3400;
    r.dev.begin();
    ref.dev.begin();
    r.run(20);
    ref.run(20);
    r.hal.frames();
    r.send(frameOf(CMD_SAVE_CALIBRATION, 7, {}));
    CHECK(count(r.hal.frames(), PKT_REPLY) == 0);  // not yet: one byte is being written
    int ticks = 0, replies = 0;
    while (replies == 0 && ticks < 200) {
        int before = r.hal.eeprom_bytes_written;
        r.run(1);
        ref.run(1);
        CHECK(r.hal.eeprom_bytes_written - before <= 1);
        ++ticks;
        for (auto& p : r.hal.frames())
            if (p[0] == PKT_REPLY) {
                ++replies;
                CHECK(p[2] == 7);
                CHECK(p[4] == RESULT_OK);
            }
    }
    // every byte of the image differs from the erased EEPROM: one a period, then the REPLY
    CHECK(r.hal.eeprom_bytes_written == CALIBRATION_EEPROM_LEN);
    CHECK(ticks == CALIBRATION_EEPROM_LEN);
    CHECK((r.dev.calibrationState() & CAL_FROM_EEPROM));
    Calibration back;
    CHECK(readCalibrationImage(r.hal.eeprom, back));
    // the sample periods ran as without the save: the same orientation, an update every period
    int16_t q[4], qr[4];
    r.dev.orientationQ14(q);
    ref.dev.orientationQ14(qr);
    for (int i = 0; i < 4; ++i) CHECK(q[i] == qr[i]);
    CHECK(r.hal.pin_pulses == ref.hal.pin_pulses);
    // saved again unchanged: nothing to write, the REPLY at once
    r.send(frameOf(CMD_SAVE_CALIBRATION, 8, {}));
    auto f = r.hal.frames();
    REQUIRE(count(f, PKT_REPLY) == 1);
    CHECK(first(f, PKT_REPLY)->at(4) == RESULT_OK);
    CHECK(r.hal.eeprom_bytes_written == CALIBRATION_EEPROM_LEN);
}

TEST_CASE("while a block is being written: another store, LOAD and REBOOT are busy, other commands are answered") {
    Rig r;
    r.hal.eeprom_write_us = 3400;
    r.dev.begin();
    r.run(5);
    r.hal.frames();
    r.send(frameOf(CMD_SAVE_CALIBRATION, 1, {}));
    r.send(frameOf(CMD_SET_BOARD, 2, {BOARD_GY85}));
    r.send(frameOf(CMD_LOAD_CALIBRATION, 3, {}));
    r.send(frameOf(CMD_REBOOT, 4, {0x07, 0xB0}));
    r.send(frameOf(CMD_GET_STATUS, 5, {}));
    auto f = r.hal.frames();
    std::vector<std::pair<int, int>> replies;
    for (auto& p : f)
        if (p[0] == PKT_REPLY) replies.push_back({p[2], p[4]});
    CHECK(replies == std::vector<std::pair<int, int>>{{2, RESULT_BUSY}, {3, RESULT_BUSY}, {4, RESULT_BUSY}, {5, RESULT_OK}});
    CHECK(r.hal.reboots == 0);
    r.run(60);
    f = r.hal.frames();
    REQUIRE(count(f, PKT_REPLY) == 1);
    CHECK(first(f, PKT_REPLY)->at(2) == 1);
    // SET_BOARD: the profile changes when its two bytes are stored, not before
    r.send(frameOf(CMD_SET_BOARD, 6, {BOARD_GY85}));
    CHECK(r.dev.boardProfile() == BOARD_ALIGNED);
    r.run(3);
    CHECK(r.dev.boardProfile() == BOARD_GY85);
    f = r.hal.frames();
    REQUIRE(count(f, PKT_REPLY) == 1);
    CHECK(first(f, PKT_REPLY)->at(4) == RESULT_OK);
}

TEST_CASE("an EEPROM write that fails half way answers STORAGE_ERROR and leaves the EEPROM's block invalid") {
    Rig r;
    r.hal.eeprom_write_us = 3400;
    r.dev.begin();
    r.send(frameOf(CMD_SAVE_CALIBRATION, 1, {}));
    r.run(10);
    r.hal.eeprom_fails = true;
    r.run(5);
    auto f = r.hal.frames();
    REQUIRE(count(f, PKT_REPLY) == 1);
    CHECK(first(f, PKT_REPLY)->at(4) == RESULT_STORAGE_ERROR);
    Calibration back;
    CHECK_FALSE(readCalibrationImage(r.hal.eeprom, back));
    CHECK_FALSE((r.dev.calibrationState() & CAL_FROM_EEPROM));
}

TEST_CASE("RAW_SAMPLE is on the wire before the MARG update starts, ORIENTATION after it") {
    Rig r;
    r.dev.begin();
    r.run(2);
    r.hal.wire.clear();
    r.hal.wire_at_pin.clear();
    r.run(1);  // a period with both (the ORIENTATION every second one)
    // when the timing pin rose, the wire held the RAW_SAMPLE's frame (up to its delimiter) and nothing else
    REQUIRE(r.hal.wire_at_pin.size() == 1);
    size_t raw_len = (size_t)(std::find(r.hal.wire.begin(), r.hal.wire.end(), 0) - r.hal.wire.begin()) + 1;
    CHECK(r.hal.wire_at_pin.back() == raw_len);
    CHECK(r.hal.wire.size() > raw_len);
    auto f = r.hal.frames();
    REQUIRE(f.size() == 2);
    CHECK(f[0][0] == PKT_RAW_SAMPLE);
    CHECK(f[1][0] == PKT_ORIENTATION);
}
