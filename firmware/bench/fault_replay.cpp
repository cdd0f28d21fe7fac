// Replays 200 Hz chip samples (device_replay's input) through the real SphereDevice twice, without and
// with one fault at a time, and prints how far the faulty run's ORIENTATION is from the fault-free one
// 2 s after each fault ended: the soak's orientation_excess_deg check (host/sphere/sim/soak.py), natively,
// on many faults. Used to find why the device stays off after short faults (firmware/README.md, "soak").
//
//   fault_replay IN.bin KIND TICKS FIRST EVERY
//
// KIND: nack (the ITG-3200 does not answer for TICKS periods) or stall (the sample clock stops for TICKS
// periods: the bus is held, the next period comes late). Faults start at period FIRST, FIRST + EVERY, …
// Prints one line per fault (start period, degrees 2 s after it ended) and the mean and max.
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <vector>

#include "fakes.h"

using namespace sphere;

static std::vector<int16_t> load(const char* path, uint32_t& n) {
    FILE* in = std::fopen(path, "rb");
    char magic[8];
    std::vector<int16_t> s;
    if (!in || std::fread(magic, 1, 8, in) != 8 || std::memcmp(magic, "SPHREPLY", 8) != 0 || std::fread(&n, 4, 1, in) != 1) {
        std::fprintf(stderr, "fault_replay: %s is not a replay file (SPHREPLY header)\n", path);
        std::exit(1);
    }
    s.resize((size_t)n * 9);
    if (std::fread(s.data(), 2, s.size(), in) != s.size()) {
        std::fprintf(stderr, "fault_replay: %s is shorter than its header says\n", path);
        std::exit(1);
    }
    std::fclose(in);
    return s;
}

// The ORIENTATION quaternion after every period; a fault covers periods [f0, f0 + ticks).
static std::vector<double> run(const std::vector<int16_t>& s, uint32_t n, int kind, uint32_t f0, uint32_t ticks) {
    FakeBus bus;
    FakeHal hal;
    SphereDevice dev(bus, hal);
    const int16_t* r = s.data();
    bus.setAccel(r[0], r[1], r[2]);
    bus.setGyro(r[3], r[4], r[5]);
    bus.setMag(r[6], r[7], r[8]);
    dev.begin();
    std::vector<double> q((size_t)n * 4);
    int16_t o[4] = {16384, 0, 0, 0};
    for (uint32_t i = 0; i < n; ++i, r += 9) {
        bool in_fault = i >= f0 && i < f0 + ticks;
        bus.setAccel(r[0], r[1], r[2]);
        bus.setGyro(r[3], r[4], r[5]);
        bus.setMag(r[6], r[7], r[8]);
        hal.now += 5000;
        bus.itg.present = !(kind == 0 && in_fault);
        if (!(kind == 1 && in_fault)) {
            dev.tick();
            hal.wire.clear();
            dev.orientationQ14(o);
        }
        for (int k = 0; k < 4; ++k) q[4 * i + k] = o[k] / 16384.0;
    }
    return q;
}

int main(int argc, char** argv) {
    if (argc != 6) {
        std::fprintf(stderr, "usage: fault_replay IN.bin nack|stall TICKS FIRST EVERY\n");
        return 2;
    }
    uint32_t n = 0;
    std::vector<int16_t> s = load(argv[1], n);
    int kind = std::strcmp(argv[2], "stall") == 0 ? 1 : 0;
    uint32_t ticks = (uint32_t)std::atoi(argv[3]), first = (uint32_t)std::atoi(argv[4]), every = (uint32_t)std::atoi(argv[5]);
    std::vector<double> ref = run(s, n, -1, 0, 0);
    double sum = 0, worst = 0;
    int count = 0;
    for (uint32_t f0 = first; f0 + ticks + 400 < n; f0 += every) {
        std::vector<double> q = run(s, n, kind, f0, ticks);
        size_t k = 4 * (size_t)(f0 + ticks + 400);
        double dot = 0, na = 0, nb = 0;
        for (int j = 0; j < 4; ++j) {
            dot += q[k + j] * ref[k + j];
            na += q[k + j] * q[k + j];
            nb += ref[k + j] * ref[k + j];
        }
        double deg = 2 * std::acos(std::fmin(1.0, std::fabs(dot) / std::sqrt(na * nb))) * 180 / M_PI;
        std::printf("%u %.2f\n", f0, deg);
        sum += deg;
        worst = std::fmax(worst, deg);
        ++count;
    }
    std::printf("mean %.2f max %.2f over %d faults\n", count ? sum / count : 0.0, worst, count);
    return 0;
}
