// Issue 12 on the native build: glitches, missing sensors, overruns, command bursts, board profiles,
// the QMC5883L, the HMC5883L's data-ready and overflow, bias tracking and the input gates.
#include <cmath>

#include "doctest_include.h"

#include "bytes.h"
#include "fakes.h"

using namespace sphere;

namespace {

typedef std::vector<std::vector<uint8_t>> Frames;

struct Bench {
    FakeBus bus;
    FakeHal hal;
    SphereDevice dev{bus, hal};
    int16_t gyro[3] = {0, 0, 0};
    explicit Bench(bool start = true) {
        bus.setAccel(0, 0, 256);
        bus.setGyro(0, 0, 0);
        bus.setMag(300, 0, -400);
        if (start) dev.begin();
    }
    void tick(uint32_t dt_us = 5000) {
        hal.now += dt_us;
        bus.setMag(300, 0, -400);  // a conversion is ready whenever the firmware looks
        dev.tick();
    }
    void run(int n) {
        for (int i = 0; i < n; ++i) tick();
    }
    Frames frames() { return hal.frames(); }
    // the quaternion the filter holds, as doubles
    void quat(double q[4]) const {
        const int32_t* s = dev.filter().quaternionQ30();
        for (int i = 0; i < 4; ++i) q[i] = s[i] / 1073741824.0;
    }
};

double angleDeg(const double a[4], const double b[4]) {
    double d = std::fabs(a[0] * b[0] + a[1] * b[1] + a[2] * b[2] + a[3] * b[3]);
    return 2 * std::acos(std::min(1.0, d)) * 180 / M_PI;
}

// the same, exact for small angles too (2·acos of a dot product near 1 loses them to the norms' rounding)
double angleDegPrecise(const double a[4], const double b[4]) {
    // e = a* ⊗ b
    double w = a[0] * b[0] + a[1] * b[1] + a[2] * b[2] + a[3] * b[3];
    double x = a[0] * b[1] - a[1] * b[0] - a[2] * b[3] + a[3] * b[2];
    double y = a[0] * b[2] + a[1] * b[3] - a[2] * b[0] - a[3] * b[1];
    double z = a[0] * b[3] - a[1] * b[2] + a[2] * b[1] - a[3] * b[0];
    return 2 * std::atan2(std::sqrt(x * x + y * y + z * z), std::fabs(w)) * 180 / M_PI;
}

const std::vector<uint8_t>* lastOf(const Frames& f, uint8_t type) {
    const std::vector<uint8_t>* p = nullptr;
    for (auto& x : f)
        if (x[0] == type) p = &x;
    return p;
}

}  // namespace

TEST_CASE("a failed read holds the last sample (stale); 10 in a row make the sensor missing; re-probed next period") {
    Bench b;
    b.run(20);
    b.bus.setGyro(100, -50, 25);
    b.run(1);
    b.frames();
    b.bus.itg.present = false;  // one glitch
    b.run(1);
    auto f = b.frames();
    const auto* raw = lastOf(f, PKT_RAW_SAMPLE);
    REQUIRE(raw);
    uint8_t flags = (*raw)[2 + 4];
    CHECK((flags & RAW_GYRO_OK));
    CHECK((flags & RAW_GYRO_STALE));
    CHECK_FALSE((flags & RAW_ACCEL_STALE));
    CHECK(getI16(raw->data() + 2 + 11) == 100);  // held
    CHECK(b.dev.status().i2c_errors[1] == 1);
    CHECK((b.dev.sensorsOk() & SENSOR_ITG3200));
    b.bus.itg.present = true;
    b.run(1);
    f = b.frames();
    CHECK_FALSE(((*lastOf(f, PKT_RAW_SAMPLE))[2 + 4] & RAW_GYRO_STALE));
    // ten failures in a row: missing
    b.bus.itg.present = false;
    b.run(SphereDevice::MISSING_AFTER - 1);
    CHECK((b.dev.sensorsOk() & SENSOR_ITG3200));
    b.run(1);
    CHECK_FALSE((b.dev.sensorsOk() & SENSOR_ITG3200));
    CHECK(b.dev.status().sensor_losses == 1);
    CHECK(b.dev.status().i2c_errors[1] == 1 + SphereDevice::MISSING_AFTER);
    f = b.frames();
    const auto* last = lastOf(f, PKT_RAW_SAMPLE);
    CHECK_FALSE(((*last)[2 + 4] & RAW_GYRO_OK));
    CHECK(getI16(last->data() + 2 + 11) == 0);  // a missing sensor's values are 0
    // probed every period, each failure counted
    b.run(3);
    CHECK(b.dev.status().probe_failures == 3);
    b.bus.itg.present = true;
    b.run(1);  // found again at the next period's probe
    CHECK((b.dev.sensorsOk() & SENSOR_ITG3200));
    b.run(1);
    f = b.frames();
    CHECK(((*lastOf(f, PKT_RAW_SAMPLE))[2 + 4] & RAW_GYRO_OK));
    CHECK(b.dev.status().probe_failures == 3);
    // STATUS carries the counters
    b.dev.receive(0);
    for (uint8_t x : frameOf(CMD_GET_STATUS, 1, {})) b.dev.receive(x);
    f = b.frames();
    const auto* st = lastOf(f, PKT_STATUS);
    REQUIRE(st);
    CHECK(getU16(st->data() + 2 + 25) == 3);  // probe_failures
    CHECK(getU16(st->data() + 2 + 27) == 1);  // sensor_losses
}

TEST_CASE("a single gyro glitch while turning costs almost nothing; the gyro's absence holds the orientation") {
    // 200 °/s about z: 2875 LSB
    Bench clean, glitch;
    for (Bench* b : {&clean, &glitch}) {
        b->run(450);  // start-up bias and convergence
        b->bus.setGyro(0, 0, 2875);
    }
    for (int i = 0; i < 200; ++i) {
        glitch.bus.itg.present = !(i == 100 || i == 101);  // a 6 ms NACK: two failed reads
        clean.tick();
        glitch.tick();
    }
    double a[4], g[4];
    clean.quat(a);
    glitch.quat(g);
    CHECK(angleDeg(a, g) < 0.5);  // the held sample is the rate the gyro had
    // gyro gone: held, flagged, not integrated as still
    glitch.bus.itg.present = false;
    glitch.run(SphereDevice::MISSING_AFTER);
    glitch.frames();
    int32_t before[4];
    std::memcpy(before, glitch.dev.filter().quaternionQ30(), sizeof before);
    glitch.run(50);
    CHECK(std::memcmp(before, glitch.dev.filter().quaternionQ30(), sizeof before) == 0);  // not one LSB moved
    auto f = glitch.frames();
    const auto* o = lastOf(f, PKT_ORIENTATION);
    REQUIRE(o);
    CHECK(((*o)[2 + 4] & ORI_GYRO_MISSING));
}

TEST_CASE("after an overrun the filter integrates the real interval") {
    Bench steady, stalled;
    for (Bench* b : {&steady, &stalled}) {
        b->run(450);
        b->bus.setGyro(0, 0, 1438);  // 100 °/s
    }
    steady.run(3);
    stalled.tick(15000);  // one period that took three
    double a[4], b[4];
    steady.quat(a);
    stalled.quat(b);
    CHECK(angleDeg(a, b) < 0.2);
    // the fixed 5 ms would have lost 3 degrees
    CHECK(angleDeg(a, b) < 3.0 / 4);
}

TEST_CASE("ten GET_CALIBRATION back to back get ten replies, in order, none dropped") {
    Bench b;
    b.run(5);
    b.frames();
    std::vector<uint8_t> burst;
    for (uint8_t s = 0; s < 10; ++s) {
        auto c = frameOf(CMD_GET_CALIBRATION, s, {});
        burst.insert(burst.end(), c.begin(), c.end());
    }
    CHECK(burst.size() <= 64);  // they all fit the UART's receive buffer
    // the UART drains about 57 bytes per 5 ms period at 115200 baud into a 128-byte ring
    int room = 128 - 40;  // a period's stream already queued
    size_t i = 0;
    int waits = 0;
    std::vector<int> seqs;
    while (i < burst.size()) {
        size_t before = b.hal.wire.size();
        b.hal.tx_room = room;
        if (b.dev.receive(burst[i])) {
            ++i;
            room -= (int)(b.hal.wire.size() - before);
        } else {
            ++waits;  // the reply would not fit: the byte stays in the receive buffer
            room = std::min(128, room + 57);
        }
    }
    auto f = b.frames();
    for (auto& p : f)
        if (p[0] == PKT_REPLY) {
            CHECK(p[4] == RESULT_OK);
            CHECK(p.size() == 4 + 46);
            seqs.push_back(p[2]);
        }
    CHECK(seqs == std::vector<int>({0, 1, 2, 3, 4, 5, 6, 7, 8, 9}));
    CHECK(waits > 0);
    CHECK(b.dev.status().frames_dropped == 0);
}

TEST_CASE("SET_BOARD maps each chip's axes into the body frame and is kept in EEPROM") {
    Bench b;
    b.bus.setAccel(1, 2, 256);
    b.bus.setGyro(10, 20, 30);
    b.run(3);
    for (uint8_t x : frameOf(CMD_SET_BOARD, 1, {BOARD_GY85})) b.dev.receive(x);
    auto f = b.frames();
    REQUIRE(lastOf(f, PKT_REPLY));
    CHECK((*lastOf(f, PKT_REPLY))[4] == RESULT_OK);
    b.bus.setAccel(1, 2, 256);
    b.bus.setGyro(10, 20, 30);
    b.run(2);
    f = b.frames();
    const auto* raw = lastOf(f, PKT_RAW_SAMPLE);
    REQUIRE(raw);
    const uint8_t* r = raw->data() + 2 + 5;
    CHECK(getI16(r + 0) == 1);  // accelerometer: the body frame
    CHECK(getI16(r + 4) == 256);
    CHECK(getI16(r + 6) == -10);  // GY-85 gyro: (−x, −y, +z)
    CHECK(getI16(r + 8) == -20);
    CHECK(getI16(r + 10) == 30);
    CHECK(getI16(r + 12) == 0);    // GY-85 mag (−y, +x, +z) of (300, 0, −400)
    CHECK(getI16(r + 14) == 300);
    CHECK(getI16(r + 16) == -400);
    // a new power-up finds the profile, and says so in HELLO
    Bench b2(false);
    std::memcpy(b2.hal.eeprom, b.hal.eeprom, sizeof b.hal.eeprom);
    b2.dev.begin();
    f = b2.frames();
    REQUIRE(lastOf(f, PKT_HELLO));
    CHECK((*lastOf(f, PKT_HELLO))[2 + 21] == BOARD_GY85);
    // SEN-10724: the magnetometer turned 90° about z
    for (uint8_t x : frameOf(CMD_SET_BOARD, 2, {BOARD_SEN10724})) b2.dev.receive(x);
    b2.run(3);  // the first conversion is read in the 2nd period, after its RAW_SAMPLE: the 3rd carries it
    f = b2.frames();
    r = lastOf(f, PKT_RAW_SAMPLE)->data() + 2 + 5;
    CHECK(getI16(r + 12) == 0);     // +y
    CHECK(getI16(r + 14) == -300);  // −x
    // out of range: bad_value; a damaged EEPROM byte pair: aligned
    for (uint8_t x : frameOf(CMD_SET_BOARD, 3, {3})) b2.dev.receive(x);
    f = b2.frames();
    CHECK((*lastOf(f, PKT_REPLY))[4] == RESULT_BAD_VALUE);
    CHECK(b2.dev.boardProfile() == BOARD_SEN10724);
    Bench b3(false);
    std::memcpy(b3.hal.eeprom, b2.hal.eeprom, sizeof b.hal.eeprom);
    b3.hal.eeprom[SphereDevice::BOARD_EEPROM_ADDR + 1] ^= 0x40;
    b3.dev.begin();
    CHECK(b3.dev.boardProfile() == BOARD_ALIGNED);
    // a failing EEPROM: storage_error, profile unchanged
    b3.hal.eeprom_fails = true;
    for (uint8_t x : frameOf(CMD_SET_BOARD, 4, {BOARD_GY85})) b3.dev.receive(x);
    f = b3.frames();
    CHECK((*lastOf(f, PKT_REPLY))[4] == RESULT_STORAGE_ERROR);
    CHECK(b3.dev.boardProfile() == BOARD_ALIGNED);
}

TEST_CASE("axis maps: signed permutations, the magnetometer's overflow mark kept") {
    // a gyro reading of −4096 (−285 °/s) on a negated axis is +285 °/s: the overflow mark is the
    // magnetometer's only (kept for the gyro, it flipped a sample of a fast turn in the soak: a 2.2° step)
    int16_t v[3] = {-4096, 5, -32768};
    mapAxes(BOARD_GY85, CHIP_GYRO, v);  // (−x, −y, +z)
    CHECK(v[0] == 4096);
    CHECK(v[1] == -5);
    CHECK(v[2] == -32768);
    int16_t w[3] = {7, -32768, 9};
    mapAxes(BOARD_SEN10724, CHIP_MAG, w);  // (+y, −x, +z)
    CHECK(w[0] == -32768);
    CHECK(w[1] == -7);
    CHECK(w[2] == 9);
    int16_t o[3] = {-4096, 3, 9};
    mapAxes(BOARD_SEN10724, CHIP_MAG, o);  // the overflow mark on the magnetometer's x stays −4096 on body y
    CHECK(o[0] == 3);
    CHECK(o[1] == -4096);
    // every profile maps every chip by a proper rotation (no mirror): determinant +1
    for (uint8_t p = 0; p < BOARD_PROFILE_COUNT; ++p)
        for (uint8_t c = 0; c < 3; ++c) {
            int m[3][3] = {};
            uint8_t a[3];
            axisMap(p, c, a);
            for (int i = 0; i < 3; ++i) m[i][a[i] & 3] = (a[i] & AXIS_NEG) ? -1 : 1;
            int det = m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1]) - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0]) +
                      m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0]);
            CHECK(det == 1);
        }
}

TEST_CASE("QMC5883L at 0x0D: found when no HMC5883L answers, converted to the HMC5883L's units") {
    Bench b(false);
    b.bus.hmc.present = false;
    b.bus.qmc.present = true;
    b.bus.setQmc(3000, -1500, 0);  // 1 G, −0.5 G, 0 at 3000 LSB/G
    b.dev.begin();
    auto f = b.frames();
    const auto* h = lastOf(f, PKT_HELLO);
    REQUIRE(h);
    CHECK(((*h)[2 + 4] & SENSOR_HMC5883L));
    CHECK((*h)[2 + 20] == MAG_CHIP_QMC5883L);
    CHECK(b.bus.qmc.regs[0x09] == 0x19);  // continuous, 100 Hz, 8 G, OSR 512
    CHECK(b.bus.qmc.regs[0x0B] == 0x01);
    b.dev.tick();
    f = b.frames();
    const auto* raw = lastOf(f, PKT_RAW_SAMPLE);
    REQUIRE(raw);  // sent before the magnetometer's poll (spec §4.2): nothing read yet
    CHECK_FALSE(((*raw)[2 + 4] & (RAW_MAG_FRESH | RAW_MAG_OK)));
    CHECK((b.bus.qmc.regs[0x06] & 1) == 0);  // DRDY cleared by the data read, after the RAW_SAMPLE
    b.dev.tick();  // this RAW_SAMPLE carries that read; no new sample since
    f = b.frames();
    raw = lastOf(f, PKT_RAW_SAMPLE);
    CHECK(((*raw)[2 + 4] & RAW_MAG_FRESH));
    CHECK(getI16(raw->data() + 2 + 17) == 1090);
    CHECK(getI16(raw->data() + 2 + 19) == -545);
    b.dev.tick();  // no new sample: not fresh, value held
    f = b.frames();
    CHECK_FALSE(((*lastOf(f, PKT_RAW_SAMPLE))[2 + 4] & RAW_MAG_FRESH));
    CHECK(getI16(lastOf(f, PKT_RAW_SAMPLE)->data() + 2 + 17) == 1090);
    b.bus.setQmc(32767, 0, 0, true);  // OVL
    b.dev.tick();
    b.dev.tick();
    f = b.frames();
    CHECK(getI16(lastOf(f, PKT_RAW_SAMPLE)->data() + 2 + 17) == -4096);
}

TEST_CASE("HMC5883L: mag_fresh only for a new conversion; overflow checked on the chip's reading") {
    Bench b;
    b.run(10);
    b.frames();
    // no conversion ends (RDY stays clear after the trigger): never fresh
    for (int i = 0; i < 5; ++i) {
        b.hal.now += 5000;
        b.dev.tick();
    }
    auto f = b.frames();
    int first = 1;  // the first carries the read of the period before (RAW_SAMPLE goes before the poll)
    for (auto& p : f)
        if (p[0] == PKT_RAW_SAMPLE && !first--) CHECK_FALSE((p[2 + 4] & RAW_MAG_FRESH));
    b.run(20);  // a conversion ready at every look: fresh every second period (100 Hz)
    f = b.frames();
    int fresh = 0, raws = 0;
    for (auto& p : f)
        if (p[0] == PKT_RAW_SAMPLE) {
            ++raws;
            fresh += (p[2 + 4] & RAW_MAG_FRESH) != 0;
        }
    CHECK(raws == 20);
    CHECK(fresh == 10);
    // −4096 on the chip's x: RAW carries it, the filter leaves the magnetometer out
    b.bus.setMag(-4096, 0, -400);
    b.hal.now += 5000;
    b.dev.tick();
    b.hal.now += 5000;
    b.dev.tick();
    f = b.frames();
    CHECK(getI16(lastOf(f, PKT_RAW_SAMPLE)->data() + 2 + 17) == -4096);
    CHECK(((*lastOf(f, PKT_ORIENTATION))[2 + 4] & ORI_MAG_REJECTED));
}

TEST_CASE("reset cause in HELLO") {
    Bench b(false);
    b.hal.reset_cause = RESET_WATCHDOG;
    b.dev.begin();
    auto f = b.frames();
    CHECK((*lastOf(f, PKT_HELLO))[2 + 19] == RESET_WATCHDOG);
}

TEST_CASE("gyro bias is tracked whenever the sphere is still, a few LSB per window") {
    Bench b(false);
    b.bus.setGyro(5, -7, 1);
    b.dev.begin();
    b.run(210);
    CHECK((int)b.dev.calibration().gyro_bias[0] == 5);
    b.bus.setGyro(11, -7, 1);  // warmed up: the bias moved
    b.run(SphereDevice::TRACK_SAMPLES + 5);
    CHECK((int)b.dev.calibration().gyro_bias[0] == 5 + SphereDevice::TRACK_STEP_LSB);
    b.run(3 * (SphereDevice::TRACK_SAMPLES + 5));
    CHECK((int)b.dev.calibration().gyro_bias[0] == 11);
    CHECK((int)b.dev.calibration().gyro_bias[1] == -7);
    // moving: no window completes, the bias stays
    for (int i = 0; i < 2 * SphereDevice::TRACK_SAMPLES; ++i) {
        b.bus.setGyro((int16_t)(11 + 40 * (i % 2)), -7, 1);
        b.tick();
    }
    CHECK((int)b.dev.calibration().gyro_bias[0] == 11);
}

TEST_CASE("input gates: accelerometer norm; magnetometer norm and dip against a learned reference") {
    InputGates g;
    const int16_t level[3] = {0, 0, 256}, swing[3] = {0, 100, 300}, up[3] = {0, 0, 16384};
    CHECK(g.accel(level));
    CHECK_FALSE(g.accel(swing));  // 1.22 g
    const int16_t field[3] = {300, 0, -400};  // 0.46 gauss, dipping 53° down
    CHECK(g.mag(field, up, false));
    CHECK(g.hasReference());
    CHECK(std::abs(g.refNorm() - 500) <= 1);
    for (int i = 0; i < 50; ++i) CHECK(g.mag(field, up, false));
    const int16_t stronger[3] = {390, 0, -520};  // +30 %: a magnet near
    CHECK_FALSE(g.mag(stronger, up, false));
    const int16_t tilted[3] = {480, 0, -140};  // same norm, dip 16°: a magnet's field added
    CHECK_FALSE(g.mag(tilted, up, false));
    const int16_t turned[3] = {0, 300, -400};  // the sphere turned about the vertical: same field
    CHECK(g.mag(turned, up, false));
    const int16_t overflow[3] = {-4096, 0, 0};
    CHECK_FALSE(g.mag(overflow, up, false));
    // rejected for relearn_after samples in a row: somewhere else now, learned anew
    for (int i = 0; i < GateSettings::DEFAULTS.relearn_after; ++i) g.mag(stronger, up, false);
    CHECK(g.mag(stronger, up, false));
    CHECK(std::abs(g.refNorm() - 650) <= 1);
    // with a hold, a rejection outlasts its cause by that many samples
    GateSettings h = GateSettings::DEFAULTS;
    h.hold = 2;
    InputGates gh(h);
    CHECK(gh.accel(level));
    CHECK_FALSE(gh.accel(swing));
    CHECK_FALSE(gh.accel(level));
    CHECK_FALSE(gh.accel(level));
    CHECK(gh.accel(level));
}

TEST_CASE("ORIENTATION bits 5-7 carry the previous update's decisions") {
    Bench b;
    b.run(450);
    b.frames();
    b.bus.setAccel(0, 100, 300);  // 1.22 g: rejected
    b.run(1);
    b.bus.setAccel(0, 0, 256);
    b.run(1);
    CHECK_FALSE((b.dev.orientationFlags() & ORI_ACCEL_REJECTED));
    CHECK(((b.dev.orientationFlags() >> ORI_PREV_SHIFT) & ORI_ACCEL_REJECTED));
    CHECK(((b.dev.orientationFlags() >> ORI_PREV_SHIFT) & ORI_MAG_USED) == 0);  // IMU-only without the accelerometer
}

TEST_CASE("gyro bias: a still window with a noisy field is accepted; a slow turn shows in the halves' means") {
    GyroBiasEstimator e;
    const int16_t a[3] = {0, 0, 256};
    // a module's field noise of ±15 LSB (the BROAD recordings'): still, the mean is the bias
    e.start(SphereDevice::TRACK_SAMPLES);
    int8_t r = 0;
    uint32_t seed = 12345;
    for (int i = 0; i < SphereDevice::TRACK_SAMPLES && r == 0; ++i) {
        int16_t n[3];
        for (int k = 0; k < 3; ++k) {
            seed = seed * 1103515245u + 12345u;
            n[k] = (int16_t)((int)((seed >> 16) % 31) - 15);
        }
        int16_t g[3] = {(int16_t)(7 + n[0] / 5), -3, -4}, m[3] = {(int16_t)(300 + n[0]), n[1], (int16_t)(-400 + n[2])};
        r = e.update(g, a, m);
    }
    CHECK(r == 1);
    CHECK(e.bias()[0] == 7);
    // a magnetometer glitch (no reading for 20 periods in the second half) does not end a still window
    e.start(SphereDevice::TRACK_SAMPLES);
    r = 0;
    const int16_t g0[3] = {7, -3, -4}, m0[3] = {300, 0, -400};
    for (int i = 0; i < SphereDevice::TRACK_SAMPLES && r == 0; ++i)
        r = e.update(g0, a, (i >= 300 && i < 320) ? nullptr : m0);
    CHECK(r == 1);
    // 3 °/s about the vertical for 1 s: each reading within the per-reading span, the halves' means not
    e.start(SphereDevice::TRACK_SAMPLES);
    r = 0;
    const int16_t g[3] = {7, -3, -4};
    for (int i = 0; i < SphereDevice::TRACK_SAMPLES && r == 0; ++i) {
        double h = 3.0 * i / 200.0 * M_PI / 180;
        int16_t m[3] = {(int16_t)std::lround(300 * std::cos(h)), (int16_t)std::lround(-300 * std::sin(h)), -400};
        r = e.update(g, a, m);
    }
    CHECK(r == -1);
}

TEST_CASE("ORIENTATION carries the state predicted GYRO_DELAY_US ahead at the current rate") {
    Bench b;
    b.run(450);
    b.bus.setGyro(0, 0, 1438);  // 100 °/s about z
    b.run(11);
    b.frames();
    int16_t state[4], sent[4];
    Frames f;
    for (int i = 0; i < 2 && !lastOf(f, PKT_ORIENTATION); ++i) {  // the period that sends ORIENTATION
        b.run(1);
        f = b.frames();
    }
    b.dev.filter().quaternionQ14(state);
    b.dev.orientationQ14(sent);
    double qs[4], qp[4];
    for (int i = 0; i < 4; ++i) {
        qs[i] = state[i] / 16384.0;
        qp[i] = sent[i] / 16384.0;
    }
    CHECK(angleDegPrecise(qs, qp) == doctest::Approx(100.0 * SphereDevice::GYRO_DELAY_US * 1e-6).epsilon(0.03));
    // ahead about +z: the yaw of the prediction is the larger
    CHECK(std::atan2(2 * (qp[0] * qp[3]), 1 - 2 * qp[3] * qp[3]) > std::atan2(2 * (qs[0] * qs[3]), 1 - 2 * qs[3] * qs[3]));
    const auto* o = lastOf(f, PKT_ORIENTATION);
    REQUIRE(o);
    for (int i = 0; i < 4; ++i) CHECK((int16_t)getU16(&(*o)[2 + 5 + 2 * i]) == sent[i]);
    // without a gyroscope nothing is predicted
    b.bus.itg.present = false;
    b.run(SphereDevice::MISSING_AFTER + 2);
    b.dev.filter().quaternionQ14(state);
    b.dev.orientationQ14(sent);
    for (int i = 0; i < 4; ++i) CHECK(std::abs(state[i] - sent[i]) <= 1);  // renormalised only
}

TEST_CASE("a gap in the gyro's samples is bridged by the trapezoid rule: NACKs held or missing, overruns") {
    // the rate ramps up by 60 LSB (4.2 °/s) per period about z: the rotation over a gap is the mean
    // of the rates at its ends times its length, which a held or a late rate misses by degrees
    auto ramp = [](Bench& b, int i) { b.bus.setGyro(0, 0, (int16_t)(60 * i)); };
    for (int gap : {2, 9, 14}) {  // stale only; stale, then missing (after MISSING_AFTER), then re-probed
        Bench clean, nack;
        clean.run(450);
        nack.run(450);
        for (int i = 0; i < 80; ++i) {
            ramp(clean, i);
            ramp(nack, i);
            nack.bus.itg.present = !(i >= 20 && i < 20 + gap);
            clean.tick();
            nack.tick();
        }
        double a[4], b[4];
        clean.quat(a);
        nack.quat(b);
        CAPTURE(gap);
        // without the bridge: 0.06°, 0.94°, 4.8° (the gradient steps the missing periods did not take are
        // most of what is left)
        CHECK(angleDegPrecise(a, b) < (gap < 10 ? 0.05 : 0.2));
    }
    Bench steady, late;
    steady.run(450);
    late.run(450);
    for (int i = 0; i < 40; ++i) {
        ramp(steady, i);
        steady.tick();
        if (i < 20 || i >= 24) {
            ramp(late, i);
            late.tick(i == 24 ? 25000 : 5000);  // periods 20 … 23 not run: the bus was held
        }
    }
    double a[4], b[4];
    steady.quat(a);
    late.quat(b);
    CHECK(angleDegPrecise(a, b) < 0.15);  // the late rate for the whole 25 ms: 0.28°
}

// ---------------------------------------------------------------- the gyro bias kept over a warm reset
namespace {

// A reset of the AVR: the program starts again (a new SphereDevice in the same storage, begin()), the RAM the
// C start-up leaves alone (FakeHal::kept) and the chips (FakeBus) as they were.
void resetDevice(Bench& b, uint8_t cause) {
    b.hal.reset_cause = cause;
    b.dev.~SphereDevice();
    new (&b.dev) SphereDevice(b.bus, b.hal);
    b.dev.begin();
}

// turning: no still window can complete
void turn(Bench& b, int ticks) {
    for (int i = 0; i < ticks; ++i) {
        b.bus.setGyro((int16_t)(5 + 60 * (i % 2)), -7, 1);
        b.tick();
    }
}

int biasX(const Bench& b) { return b.dev.calibration().gyro_bias[0]; }

// a Bench whose bias (5, −7, 1) was estimated at power-up, then the sphere turns
void tracked(Bench& b) {
    b.bus.setGyro(5, -7, 1);
    b.dev.begin();
    b.run(210);
    REQUIRE(biasX(b) == 5);
    turn(b, 20);
}

}  // namespace

// cause 0: unknown (the Nano's Optiboot 4.4 cleared MCUSR and handed nothing over): the record alone decides
TEST_CASE("a reset that is not a power-on keeps the tracked gyro bias; the HELLO says why it reset") {
    for (uint8_t cause : {RESET_EXTERNAL, RESET_WATCHDOG, RESET_BROWN_OUT, (uint8_t)(RESET_EXTERNAL | RESET_WATCHDOG),
                          (uint8_t)0}) {
        CAPTURE((int)cause);
        Bench b(false);
        tracked(b);
        b.frames();
        resetDevice(b, cause);  // mid-turn
        CHECK(biasX(b) == 5);
        CHECK((int)b.dev.calibration().gyro_bias[1] == -7);
        CHECK((int)b.dev.calibration().gyro_bias[2] == 1);
        const uint8_t* h = lastOf(b.frames(), PKT_HELLO)->data() + 2;
        CHECK(h[19] == cause);  // reset_cause
        CHECK((h[18] & (CAL_GYRO_BIAS_VALID | CAL_GYRO_BIAS_ESTIMATED)) == (CAL_GYRO_BIAS_VALID | CAL_GYRO_BIAS_ESTIMATED));
        // no power-up estimate replaces it: still windows move it by TRACK_STEP_LSB at most
        turn(b, 100);
        b.bus.setGyro(25, -7, 1);
        b.run(SphereDevice::TRACK_SAMPLES + 5);
        CHECK(biasX(b) == 5 + SphereDevice::TRACK_STEP_LSB);
        // and what was tracked after the reset is kept over the next one
        resetDevice(b, RESET_WATCHDOG);
        CHECK(biasX(b) == 5 + SphereDevice::TRACK_STEP_LSB);
    }
}

TEST_CASE("the kept gyro bias is ignored after a power-on, with a bad check word or past the plausible range") {
    SUBCASE("power-on (PORF), also beside another flag: the RAM is not defined") {
        for (uint8_t cause : {RESET_POWER_ON, (uint8_t)(RESET_POWER_ON | RESET_EXTERNAL)}) {
            Bench b(false);
            tracked(b);
            REQUIRE(keptBiasValid(b.hal.kept));
            resetDevice(b, cause);
            CHECK(biasX(b) == 0);
            CHECK_FALSE((b.dev.calibrationState() & CAL_GYRO_BIAS_VALID));
            b.bus.setGyro(9, -7, 1);  // the power-up estimate runs: the first still second sets the bias
            b.run(210);
            CHECK(biasX(b) == 9);
        }
    }
    SUBCASE("a bad check word: any one bit of the record flipped") {
        for (size_t bit = 0; bit < 8 * sizeof(KeptBias); ++bit) {
            Bench b(false);
            tracked(b);
            ((uint8_t*)&b.hal.kept)[bit / 8] ^= (uint8_t)(1u << (bit % 8));
            CHECK_FALSE(keptBiasValid(b.hal.kept));
            resetDevice(b, RESET_EXTERNAL);
            CHECK(biasX(b) == 0);
            CHECK_FALSE((b.dev.calibrationState() & CAL_GYRO_BIAS_VALID));
        }
    }
    SUBCASE("random RAM is never taken for a record") {
        uint32_t x = 12345;
        int accepted = 0;
        for (int n = 0; n < 200000; ++n) {
            KeptBias k;
            for (size_t i = 0; i < sizeof k; ++i) {
                x ^= x << 13, x ^= x >> 17, x ^= x << 5;
                ((uint8_t*)&k)[i] = (uint8_t)x;
            }
            accepted += keptBiasValid(k);
        }
        CHECK(accepted == 0);
    }
    SUBCASE("a bias past ±1000 LSB (70 °/s) is not plausible, whatever its check word") {
        Bench b(false);
        b.dev.begin();
        const int16_t edge[3] = {KEPT_BIAS_LIMIT_LSB, -KEPT_BIAS_LIMIT_LSB, 0}, past[3] = {0, 0, KEPT_BIAS_LIMIT_LSB + 1};
        keepBias(b.hal.kept, edge, CAL_GYRO_BIAS_VALID | CAL_GYRO_BIAS_ESTIMATED);
        CHECK(keptBiasValid(b.hal.kept));
        resetDevice(b, RESET_WATCHDOG);
        CHECK(biasX(b) == KEPT_BIAS_LIMIT_LSB);
        keepBias(b.hal.kept, past, CAL_GYRO_BIAS_VALID | CAL_GYRO_BIAS_ESTIMATED);
        CHECK_FALSE(keptBiasValid(b.hal.kept));
        resetDevice(b, RESET_WATCHDOG);
        CHECK((int)b.dev.calibration().gyro_bias[2] == 0);
        CHECK_FALSE((b.dev.calibrationState() & CAL_GYRO_BIAS_VALID));
    }
    SUBCASE("no bias yet, or RESET_CALIBRATION: nothing to keep") {
        Bench b(false);
        b.bus.setGyro(5, -7, 1);
        b.dev.begin();
        turn(b, 50);  // no window completed before the reset
        resetDevice(b, RESET_EXTERNAL);
        CHECK_FALSE((b.dev.calibrationState() & CAL_GYRO_BIAS_VALID));
        b.bus.setGyro(5, -7, 1);
        b.run(210);
        REQUIRE(biasX(b) == 5);
        for (uint8_t x : frameOf(CMD_RESET_CALIBRATION, 1, {})) b.dev.receive(x);
        b.tick();
        turn(b, 10);
        resetDevice(b, RESET_EXTERNAL);
        CHECK(biasX(b) == 0);
        CHECK_FALSE((b.dev.calibrationState() & CAL_GYRO_BIAS_VALID));
    }
}

TEST_CASE("the kept bias against the EEPROM's: the newer one, the EEPROM's flags when they agree") {
    Bench b(false);
    b.dev.begin();
    std::vector<uint8_t> block(42, 0);
    block[0] = 20;  // gyro bias x 20 LSB, the rest default
    for (int i = 0; i < 3; ++i) block[12 + 2 * i + 1] = 0x40;                 // accel scale 1.0 (Q14)
    for (int i = 0; i < 9; i += 4) block[24 + 2 * i + 1] = 0x40;              // soft iron identity
    for (uint8_t x : frameOf(CMD_SET_CALIBRATION, 1, block)) b.dev.receive(x);
    for (uint8_t x : frameOf(CMD_SAVE_CALIBRATION, 2, {})) b.dev.receive(x);
    turn(b, 10);
    resetDevice(b, RESET_EXTERNAL);  // the kept bias is the EEPROM's
    CHECK(biasX(b) == 20);
    CHECK((b.dev.calibrationState() & CAL_FROM_EEPROM));
    b.bus.setGyro(40, 0, 0);  // tracking moves it away from the EEPROM's
    b.run(SphereDevice::TRACK_SAMPLES + 5);
    REQUIRE(biasX(b) == 20 + SphereDevice::TRACK_STEP_LSB);
    turn(b, 10);
    resetDevice(b, RESET_EXTERNAL);
    CHECK(biasX(b) == 20 + SphereDevice::TRACK_STEP_LSB);
    CHECK_FALSE((b.dev.calibrationState() & CAL_FROM_EEPROM));
    CHECK((b.dev.calibrationState() & CAL_GYRO_BIAS_VALID));
    resetDevice(b, RESET_POWER_ON);  // a power-on: the EEPROM's
    CHECK(biasX(b) == 20);
    CHECK((b.dev.calibrationState() & CAL_FROM_EEPROM));
}

TEST_CASE("SET_BOARD to another profile: the bias of the old frame is not valid, the next still second sets it whole") {
    Bench b(false);
    tracked(b);  // aligned: bias (5, −7, 1)
    for (uint8_t x : frameOf(CMD_SET_BOARD, 1, {BOARD_GY85})) b.dev.receive(x);
    CHECK((*lastOf(b.frames(), PKT_REPLY))[4] == RESULT_OK);
    CHECK_FALSE((b.dev.calibrationState() & CAL_GYRO_BIAS_VALID));
    // a warm reset now does not bring the old frame's bias back: the power-up estimate runs
    resetDevice(b, RESET_EXTERNAL);
    b.bus.setGyro(5, -7, 1);  // the chip's bias; in the GY-85's body frame (−x, −y, +z): (−5, 7, 1)
    b.run(SphereDevice::STARTUP_BIAS_SAMPLES + 10);
    CHECK(biasX(b) == -5);
    CHECK((int)b.dev.calibration().gyro_bias[1] == 7);
    CHECK((int)b.dev.calibration().gyro_bias[2] == 1);
    CHECK((b.dev.calibrationState() & CAL_GYRO_BIAS_VALID));
    // without a reset: back to aligned, and one still window (not TRACK_STEP_LSB per window) sets it
    for (uint8_t x : frameOf(CMD_SET_BOARD, 2, {BOARD_ALIGNED})) b.dev.receive(x);
    CHECK_FALSE((b.dev.calibrationState() & CAL_GYRO_BIAS_VALID));
    b.run(2 * SphereDevice::TRACK_SAMPLES + 10);
    CHECK(biasX(b) == 5);
    CHECK((int)b.dev.calibration().gyro_bias[1] == -7);
    CHECK((b.dev.calibrationState() & CAL_GYRO_BIAS_VALID));
    // the same profile again changes nothing
    for (uint8_t x : frameOf(CMD_SET_BOARD, 3, {BOARD_ALIGNED})) b.dev.receive(x);
    CHECK((b.dev.calibrationState() & CAL_GYRO_BIAS_VALID));
}
