// The benchmark's input sequence run natively: the AVR build (inline-assembly multiplies) must end in
// exactly the same Q30 state as the portable C++ (make -C firmware bench compares the two).
#include <cstdio>

#include "marg_filter.h"

using sphere::MargFilter;

static MargFilter filter;

static void run(const char* name, bool acc, bool mag) {
    int16_t g[3], a[3], m[3];
    for (uint16_t i = 0; i < 400; ++i) {
        int16_t k = (int16_t)(i * 97);
        g[0] = (int16_t)(k * 3);
        g[1] = (int16_t)(-k);
        g[2] = (int16_t)(i & 1 ? 28750 : -350);
        a[0] = (int16_t)((i * 7) % 200 - 100);
        a[1] = (int16_t)((i * 13) % 160 - 80);
        a[2] = 240;
        m[0] = (int16_t)(300 - (i % 50));
        m[1] = (int16_t)((i * 3) % 100 - 50);
        m[2] = -380;
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
