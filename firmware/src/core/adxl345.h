// ADXL345 accelerometer (Analog Devices, rev. E) at 0x53 (SDO low): full resolution (3.9 mg/LSB,
// 256 LSB/g) at ±16 g so taps do not saturate, 400 Hz output (200 Hz bandwidth, datasheet Table 7),
// read at 200 Hz, the newest of two samples, tap / double tap / free fall engines
// routed to INT1 (wired to the Nano's D2). Every register whose value the driver relies on is written at
// start: the chip keeps its registers while powered, and a sketch flashed before may have left a FIFO mode
// (then DATAX0.. return the FIFO's oldest sample, up to 32 periods old) or offsets.
#pragma once
#include <stdint.h>

#include "i2c_bus.h"

namespace sphere {

struct TapSettings {
    uint8_t thresh_tap;  // 62.5 mg/LSB
    uint8_t dur;         // 625 µs/LSB
    uint8_t latent;      // 1.25 ms/LSB
    uint8_t window;      // 1.25 ms/LSB
    uint8_t tap_axes;    // bits 2,1,0 = x,y,z; bit 3 suppress
};

struct FreeFallSettings {
    uint8_t thresh_ff;  // 62.5 mg/LSB
    uint8_t time_ff;    // 5 ms/LSB
};

class Adxl345 {
public:
    static const uint8_t ADDRESS = 0x53;
    static const uint8_t DEVID_VALUE = 0xE5;
    enum Reg : uint8_t {
        DEVID = 0x00, THRESH_TAP = 0x1D, OFSX = 0x1E, OFSY = 0x1F, OFSZ = 0x20, DUR = 0x21, LATENT = 0x22, WINDOW = 0x23, THRESH_FF = 0x28,
        TIME_FF = 0x29, TAP_AXES = 0x2A, ACT_TAP_STATUS = 0x2B, BW_RATE = 0x2C, POWER_CTL = 0x2D,
        INT_ENABLE = 0x2E, INT_MAP = 0x2F, INT_SOURCE = 0x30, DATA_FORMAT = 0x31, DATAX0 = 0x32, FIFO_CTL = 0x38,
    };
    enum IntBit : uint8_t { INT_DATA_READY = 0x80, INT_SINGLE_TAP = 0x40, INT_DOUBLE_TAP = 0x20, INT_FREE_FALL = 0x04 };
    static const uint8_t BW_RATE_400HZ = 0x0C;
    static const uint8_t DATA_FORMAT_FULL_RES_16G = 0x0B;  // FULL_RES | range ±16 g, INT active high
    static const uint8_t POWER_CTL_MEASURE = 0x08;
    static const uint8_t EVENT_INTS = INT_SINGLE_TAP | INT_DOUBLE_TAP | INT_FREE_FALL;

    static const TapSettings DEFAULT_TAP;            // 3 g, 20 ms, 100 ms, 300 ms, x y z
    static const FreeFallSettings DEFAULT_FREE_FALL;  // 0.44 g for 150 ms

    explicit Adxl345(I2cBus& bus) : bus_(bus), devid_(0) {}

    // Reads DEVID and, when it is 0xE5, configures the chip. True when the chip is ready.
    bool begin(const TapSettings& tap, const FreeFallSettings& ff);
    uint8_t devid() const { return devid_; }
    bool readAccel(int16_t out[3]);  // one 6-byte burst from DATAX0
    bool writeTap(const TapSettings& tap);
    bool writeFreeFall(const FreeFallSettings& ff);
    // ACT_TAP_STATUS, then INT_SOURCE (read once: it clears the latched interrupt).
    bool readEvent(uint8_t& int_source, uint8_t& act_tap_status);

    // Little-endian, full resolution: sign-extended 13-bit values in 16-bit registers.
    static void decode(const uint8_t raw[6], int16_t out[3]);

private:
    I2cBus& bus_;
    uint8_t devid_;
};

}  // namespace sphere
