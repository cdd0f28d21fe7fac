// The moving sample both benchmarks feed the MARG filter (AVR cycle count in marg_bench.cpp, native
// bit-exactness check in marg_check.cpp): rates up to ±2000 °/s, tilted gravity and field. One
// definition, so the two programs cannot drift apart.
#pragma once
#include <stdint.h>

static inline void movingSample(uint16_t i, int16_t g[3], int16_t a[3], int16_t m[3]) {
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
}
