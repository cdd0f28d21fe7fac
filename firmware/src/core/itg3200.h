// ITG-3200 gyroscope (InvenSense) at 0x68 (AD0 low) or 0x69: FS_SEL = 3 (±2000 °/s,
// 14.375 LSB per °/s), 1 kHz internal rate with the 98 Hz low-pass (DLPF_CFG = 2, datasheet §8.3
// register 22; its delay, which the ITG-3200's datasheet does not give, is 2.8 ms for the same filter in
// InvenSense's MPU-6000/6050 register map, register 26: 4.8 ms at 42 Hz, 1.9 ms at 188 Hz), SMPLRT_DIV = 0:
// the output registers take every internal sample (§8.2, register 21: F_sample = F_internal /
// (SMPLRT_DIV + 1) = 1 kHz), so the 200 Hz read finds a value 0 … 1 ms old instead of 0 … 5 ms.
// 98 Hz is the widest band at or below the 100 Hz Nyquist limit of the 200 Hz read, and it was chosen over
// 42 and 188 Hz by `sphere bench drift` on its choosing seeds 1, 2, 3 (the worst pointer figure: 4.28 px/s
// against 5.13 and 4.41; firmware/README.md, "How old a sample is when it is sent").
// Data registers are big-endian.
#pragma once
#include <stdint.h>

#include "i2c_bus.h"

namespace sphere {

class Itg3200 {
public:
    static const uint8_t ADDRESS_AD0_LOW = 0x68, ADDRESS_AD0_HIGH = 0x69;
    enum Reg : uint8_t { WHO_AM_I = 0x00, SMPLRT_DIV = 0x15, DLPF_FS = 0x16, INT_CFG = 0x17, GYRO_XOUT_H = 0x1D,
                         PWR_MGM = 0x3E };
    static const uint8_t SMPLRT_DIV_1KHZ = 0;    // 1 kHz / (0 + 1)
    static const uint8_t DLPF_FS_2000DPS_98HZ = (3 << 3) | 2;
    static const uint8_t PWR_MGM_PLL_X = 0x01;   // clock from the X gyro's PLL (datasheet advice)

    explicit Itg3200(I2cBus& bus) : bus_(bus), address_(ADDRESS_AD0_LOW), whoami_(0) {}

    // Tries 0x68, then 0x69; WHO_AM_I & 0x7E must be 0x68. Configures the chip when found.
    bool begin();
    uint8_t whoami() const { return whoami_; }
    uint8_t address() const { return address_; }
    bool readGyro(int16_t out[3]);

    static bool whoamiValid(uint8_t v) { return (v & 0x7E) == 0x68; }
    static void decode(const uint8_t raw[6], int16_t out[3]);  // big-endian x, y, z

private:
    I2cBus& bus_;
    uint8_t address_;
    uint8_t whoami_;
};

}  // namespace sphere
