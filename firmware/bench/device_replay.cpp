// Replays 200 Hz chip samples through the real SphereDevice (the native build of src/core with the
// register fakes of tests/firmware/fakes.h) and writes the orientation after every period: the tool
// that chooses the input gates by leave-one-trial-out (firmware/bench/tune_gates.py, MARG_FILTER.md).
//
//   device_replay IN.bin OUT.bin [beta_milli accel_tol_lsb mag_norm_tol_q8 mag_dip_tol_q14 learn_shift relearn_after hold]
//
// IN: b"SPHREPLY", u32 n, then n records of nine int16 (accel, gyro, mag in chip units, the magnetometer
// value the chip holds at that period). OUT: n records of five int16: ORIENTATION flags, then w, x, y, z
// in Q14 (the quaternion an ORIENTATION packet of that period would carry).
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <vector>

#include "fakes.h"

using namespace sphere;

int main(int argc, char** argv) {
    if (argc != 3 && argc != 10) {
        std::fprintf(stderr, "usage: device_replay IN.bin OUT.bin [beta_milli accel_tol norm_q8 dip_q14 learn_shift relearn hold]\n");
        return 2;
    }
    FILE* in = std::fopen(argv[1], "rb");
    if (!in) {
        std::fprintf(stderr, "device_replay: cannot read %s\n", argv[1]);
        return 1;
    }
    char magic[8];
    uint32_t n = 0;
    if (std::fread(magic, 1, 8, in) != 8 || std::memcmp(magic, "SPHREPLY", 8) != 0 || std::fread(&n, 4, 1, in) != 1) {
        std::fprintf(stderr, "device_replay: %s is not a replay file (SPHREPLY header)\n", argv[1]);
        return 1;
    }
    std::vector<int16_t> s((size_t)n * 9);
    if (std::fread(s.data(), 2, s.size(), in) != s.size()) {
        std::fprintf(stderr, "device_replay: %s is shorter than its header says\n", argv[1]);
        return 1;
    }
    std::fclose(in);

    FakeBus bus;
    FakeHal hal;
    SphereDevice dev(bus, hal);
    if (argc == 10) {
        GateSettings g = GateSettings::DEFAULTS;
        g.accel_tol_lsb = (uint16_t)std::atoi(argv[4]);
        g.mag_norm_tol_q8 = (uint8_t)std::atoi(argv[5]);
        g.mag_dip_tol_q14 = (uint16_t)std::atoi(argv[6]);
        g.learn_shift = (uint8_t)std::atoi(argv[7]);
        g.relearn_after = (uint16_t)std::atoi(argv[8]);
        g.hold = (uint8_t)std::atoi(argv[9]);
        dev.gates().setSettings(g);
    }
    std::vector<int16_t> out((size_t)n * 5);
    const int16_t* r = s.data();
    bus.setAccel(r[0], r[1], r[2]);
    bus.setGyro(r[3], r[4], r[5]);
    bus.setMag(r[6], r[7], r[8]);
    dev.begin();
    if (argc == 10) {  // β as SET_FILTER sets it (kept until the start-up convergence ends)
        uint16_t beta = (uint16_t)std::atoi(argv[3]);
        uint8_t body[2] = {(uint8_t)beta, (uint8_t)(beta >> 8)}, frame[MAX_FRAME];
        size_t len = FrameEncoder::encodeWithSeq(CMD_SET_FILTER, 0, body, 2, frame);
        for (size_t k = 0; k < len; ++k) dev.receive(frame[k]);
    }
    for (uint32_t i = 0; i < n; ++i, r += 9) {
        bus.setAccel(r[0], r[1], r[2]);
        bus.setGyro(r[3], r[4], r[5]);
        bus.setMag(r[6], r[7], r[8]);  // a conversion is ready whenever the firmware looks
        hal.now += 5000;
        dev.tick();
        hal.wire.clear();
        int16_t q[4];
        dev.orientationQ14(q);
        out[5 * i] = dev.orientationFlags();
        for (int k = 0; k < 4; ++k) out[5 * i + 1 + k] = q[k];
    }
    FILE* o = std::fopen(argv[2], "wb");
    if (!o || std::fwrite(out.data(), 2, out.size(), o) != out.size()) {
        std::fprintf(stderr, "device_replay: cannot write %s\n", argv[2]);
        return 1;
    }
    std::fclose(o);
    return 0;
}
