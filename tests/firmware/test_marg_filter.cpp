// The fixed-point MargFilter against the double-precision reference of the same algorithm.
#include <dirent.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <string>
#include <vector>

#include "doctest_include.h"

#include "fixed_math.h"
#include "madgwick_ref.h"
#include "input_gates.h"
#include "marg_filter.h"
#include "test_paths.h"

using sphere::MargFilter;

static const double GYRO_RAD_PER_LSB = M_PI / 180.0 / 14.375;

static void fixedQuat(const MargFilter& f, double out[4]) {
    for (int i = 0; i < 4; ++i) out[i] = f.quaternionQ30()[i] / 1073741824.0;
}

struct Sample {
    int16_t acc[3], gyr[3], mag[3];
};

// Runs both filters over the samples; returns the RMS and max angle between them in degrees.
struct Comparison {
    double rms_deg, max_deg, final_deg;
    int mag_rejected, acc_rejected;
};

static Comparison compare(const std::vector<Sample>& s, uint16_t dt_us, uint16_t beta_milli) {
    MargFilter f(dt_us);
    f.setBetaMilli(beta_milli);
    MadgwickRef ref;
    ref.beta = beta_milli / 1000.0;
    double dt = dt_us * 1e-6, sum2 = 0, mx = 0, last = 0;
    Comparison c{};
    sphere::InputGates gates;
    for (const Sample& x : s) {
        int16_t up[3];
        f.up(up);
        bool av = gates.accel(x.acc), mv = gates.mag(x.mag, up, false);
        c.acc_rejected += !av;
        c.mag_rejected += !mv;
        f.update(x.gyr, x.acc, x.mag, av, mv);
        ref.update(x.gyr[0] * GYRO_RAD_PER_LSB, x.gyr[1] * GYRO_RAD_PER_LSB, x.gyr[2] * GYRO_RAD_PER_LSB, x.acc[0],
                   x.acc[1], x.acc[2], x.mag[0], x.mag[1], x.mag[2], dt, av, mv);
        double q[4];
        fixedQuat(f, q);
        last = quatAngleDeg(q, ref.q);
        sum2 += last * last;
        mx = std::max(mx, last);
    }
    c.rms_deg = s.empty() ? 0 : std::sqrt(sum2 / s.size());
    c.max_deg = mx;
    c.final_deg = last;
    return c;
}

TEST_CASE("normaliseQ14 is accurate to about 1e-4") {
    uint32_t seed = 12345;
    auto rnd = [&seed]() {
        seed = seed * 1103515245u + 12345u;
        return (int32_t)(seed >> 1) >> (seed & 15);
    };
    double worst = 0;
    for (int t = 0; t < 20000; ++t) {
        int32_t v[4];
        for (int i = 0; i < 4; ++i) v[i] = rnd() - (1 << 20);
        int16_t o[4];
        int n = 3 + (t & 1);
        REQUIRE(sphere::normaliseQ14(v, (uint8_t)n, o));
        double norm = 0;
        for (int i = 0; i < n; ++i) norm += double(v[i]) * v[i];
        norm = std::sqrt(norm);
        for (int i = 0; i < n; ++i) worst = std::max(worst, std::fabs(o[i] / 16384.0 - v[i] / norm));
    }
    MESSAGE("normaliseQ14 worst component error " << worst);
    CHECK(worst < 1.5e-4);
    int32_t z[3] = {0, 0, 0};
    int16_t o[3];
    CHECK_FALSE(sphere::normaliseQ14(z, 3, o));
}

TEST_CASE("at rest the fixed-point filter does not drift") {
    // level, heading 30° west of north; field 0.5 G with 60° inclination; 200 Hz
    std::vector<Sample> s(200 * 180);
    for (auto& x : s) {
        x = Sample{{0, 0, 256}, {0, 0, 0}, {0, 0, 0}};
        double h = 0.5 * 1090 * std::cos(M_PI / 3), v = -0.5 * 1090 * std::sin(M_PI / 3);
        x.mag[0] = (int16_t)std::lround(h * std::cos(M_PI / 6));
        x.mag[1] = (int16_t)std::lround(-h * std::sin(M_PI / 6));
        x.mag[2] = (int16_t)std::lround(v);
    }
    MargFilter f;
    f.setBetaMilli(MargFilter::STARTUP_BETA_MILLI);
    for (int i = 0; i < 600; ++i) f.update(s[i].gyr, s[i].acc, s[i].mag, true, true);
    f.setBetaMilli(MargFilter::DEFAULT_BETA_MILLI);
    for (int i = 0; i < 200 * 60; ++i) f.update(s[i].gyr, s[i].acc, s[i].mag, true, true);
    double a[4], b[4];
    fixedQuat(f, a);
    for (int i = 0; i < 200 * 120; ++i) f.update(s[i].gyr, s[i].acc, s[i].mag, true, true);
    fixedQuat(f, b);
    double drift = quatAngleDeg(a, b) / 2.0;  // per minute over two minutes
    MESSAGE("MARG at rest: drift " << drift << " deg/min");
    CHECK(drift < 0.1);

    // gyro only (accelerometer rejected), zero rate: exactly no motion
    MargFilter g;
    g.setQuaternion(f.quaternionQ30());
    fixedQuat(g, a);
    for (int i = 0; i < 200 * 60; ++i) g.update(s[i].gyr, s[i].acc, s[i].mag, false, false);
    fixedQuat(g, b);
    MESSAGE("gyro-only at rest: drift " << quatAngleDeg(a, b) << " deg/min");
    CHECK(quatAngleDeg(a, b) < 0.01);

    // IMU (no magnetometer)
    MargFilter h;
    for (int i = 0; i < 200 * 60; ++i) h.update(s[i].gyr, s[i].acc, s[i].mag, true, false);
    fixedQuat(h, a);
    for (int i = 0; i < 200 * 60; ++i) h.update(s[i].gyr, s[i].acc, s[i].mag, true, false);
    fixedQuat(h, b);
    MESSAGE("IMU at rest: drift " << quatAngleDeg(a, b) << " deg/min");
    CHECK(quatAngleDeg(a, b) < 0.1);
}

TEST_CASE("small rates are integrated, not lost to quantisation") {
    // 1 LSB = 0.0696 °/s about z for 60 s, gyro only: 4.17°
    MargFilter f;
    MadgwickRef ref;
    int16_t g[3] = {0, 0, 1}, a[3] = {0, 0, 256}, m[3] = {300, 0, -400};
    for (int i = 0; i < 200 * 60; ++i) {
        f.update(g, a, m, false, false);
        ref.update(0, 0, GYRO_RAD_PER_LSB, 0, 0, 1, 0, 0, 0, 0.005, false, false);
    }
    double q[4], id[4] = {1, 0, 0, 0};
    fixedQuat(f, q);
    MESSAGE("1 LSB for 60 s: fixed " << quatAngleDeg(q, id) << "°, reference " << quatAngleDeg(ref.q, id) << "°");
    CHECK(std::fabs(quatAngleDeg(q, id) - 60 / 14.375) < 0.01);
    CHECK(quatAngleDeg(q, ref.q) < 0.01);
}

TEST_CASE("no overflow at the gyroscope's full scale") {
    // ±2000 °/s and beyond (saturated −32768 … 32767) on all axes, with MARG corrections
    std::vector<Sample> s(200 * 10);
    for (size_t i = 0; i < s.size(); ++i) {
        int16_t r = (i / 200) % 2 ? -32768 : 32767;
        s[i] = Sample{{10, -20, 250}, {r, (int16_t)(-r / 2), r}, {250, 40, -300}};
        if (i % 400 > 300) s[i].gyr[1] = 28750;  // 2000 °/s
    }
    Comparison c = compare(s, 5000, 41);
    MESSAGE("full scale: RMS " << c.rms_deg << "°, max " << c.max_deg << "°");
    CHECK(c.max_deg < 0.5);
    MargFilter f;
    for (auto& x : s) f.update(x.gyr, x.acc, x.mag, true, true);
    double n = 0;
    for (int i = 0; i < 4; ++i) n += std::pow(f.quaternionQ30()[i] / 1073741824.0, 2);
    CHECK(std::fabs(std::sqrt(n) - 1) < 1e-3);
}

TEST_CASE("start-up gain converges from identity to an upside-down pose, then settles with the reference") {
    // upside down (accel −z), rotated in heading; 2 s at the start-up gain, then 5 s at the default
    Sample x{{0, 0, -256}, {0, 0, 0}, {-250, 30, 350}};
    MargFilter f;
    MadgwickRef ref;
    f.setBetaMilli(MargFilter::STARTUP_BETA_MILLI);
    ref.beta = MargFilter::STARTUP_BETA_MILLI / 1000.0;
    double q[4], worst_after = 0;
    for (int i = 0; i < 200 * 7; ++i) {
        if (i == 400) {
            f.setBetaMilli(MargFilter::DEFAULT_BETA_MILLI);
            ref.beta = MargFilter::DEFAULT_BETA_MILLI / 1000.0;
        }
        f.update(x.gyr, x.acc, x.mag, true, true);
        ref.update(0, 0, 0, x.acc[0], x.acc[1], x.acc[2], x.mag[0], x.mag[1], x.mag[2], 0.005, true, true);
        fixedQuat(f, q);
        if (i >= 600) worst_after = std::max(worst_after, quatAngleDeg(q, ref.q));
    }
    // gravity in the sensor frame from the fixed filter's q (eq. 86) points along −z
    double gz = q[0] * q[0] - q[1] * q[1] - q[2] * q[2] + q[3] * q[3];
    MESSAGE("start-up: fixed vs reference after settling: max " << worst_after << "°; g_z " << gz);
    CHECK(gz < -0.9999);
    CHECK(worst_after < 0.25);
}

static std::vector<std::string> broadFiles(const std::string& dir) {
    std::vector<std::string> out;
    if (DIR* d = opendir(dir.c_str())) {
        while (dirent* e = readdir(d)) {
            std::string n = e->d_name;
            if (n.size() > 4 && n.substr(n.size() - 4) == ".bin") out.push_back(n);
        }
        closedir(d);
    }
    std::sort(out.begin(), out.end());
    return out;
}

TEST_CASE("fixed-point filter follows the double reference on every BROAD trial (< 0.25° RMS)") {
    std::string dir = testBuildPath("broad");
    auto files = broadFiles(dir);
    if (files.empty()) {
        MESSAGE("skipped: no converted BROAD trials in " << dir
                << " (set SPHERE_BROAD_DIR to the BROAD .mat folder and install the host package)");
        return;
    }
    for (const auto& name : files) {
        FILE* fp = std::fopen((dir + "/" + name).c_str(), "rb");
        REQUIRE(fp);
        char magic[8];
        uint32_t dt_us = 0, n = 0;
        REQUIRE(std::fread(magic, 1, 8, fp) == 8);
        REQUIRE(std::memcmp(magic, "SPHBROAD", 8) == 0);
        REQUIRE(std::fread(&dt_us, 4, 1, fp) == 1);
        REQUIRE(std::fread(&n, 4, 1, fp) == 1);
        std::vector<Sample> s(n);
        REQUIRE(std::fread(s.data(), sizeof(Sample), n, fp) == n);
        std::fclose(fp);
        for (uint16_t beta : {41, 100}) {
            Comparison c = compare(s, (uint16_t)dt_us, beta);
            char line[256];
            std::snprintf(line, sizeof line,
                          "BROAD %-44s beta=%.3f n=%6u RMS %.4f deg  max %.4f deg  acc_rej %d mag_rej %d",
                          name.c_str(), beta / 1000.0, n, c.rms_deg, c.max_deg, c.acc_rejected, c.mag_rejected);
            std::printf("%s\n", line);
            CHECK(c.rms_deg < 0.25);
        }
    }
}
