// The benchmark's input sequence run natively: the AVR build (inline-assembly multiplies) must end in
// exactly the same Q30 state as the portable C++ (make -C firmware bench compares the two).
#include <cstdio>

#include "marg_filter.h"
#include "moving_sample.h"

using sphere::MargFilter;

static MargFilter filter;

static void run(const char* name, bool acc, bool mag) {
    int16_t g[3], a[3], m[3];
    for (uint16_t i = 0; i < 400; ++i) {
        movingSample(i, g, a, m);
        filter.update(g, a, m, acc, mag);
    }
    std::printf("%s: state after run:", name);
    for (int i = 0; i < 4; ++i) {
        long q = filter.quaternionQ30()[i];
        std::printf(q < 0 ? " -%ld" : " %ld", q < 0 ? -q : q);
    }
    std::printf("\n");
}

int main() {
    run("MARG (accel + mag)", true, true);
    run("IMU (accel only)", true, false);
    run("gyro only", false, false);
    filter.begin();
    run("MARG from identity", true, true);
}
