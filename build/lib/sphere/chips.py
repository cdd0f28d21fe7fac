"""The three sensor chips' output scales, shared by the protocol (chip units on the wire), the
simulated board (physical units to chip units) and the host (chip units to physical units).

Numbers from the datasheets:

- ADXL345 (Analog Devices, rev. E): full-resolution mode keeps 3.9 mg/LSB (256 LSB/g typical) at
  every range; at ±16 g the output is 13 bits, −4096…4095.
- ITG-3200 (InvenSense PS-ITG-3200A-00-01.4): 14.375 LSB/(°/s), FS_SEL = 3 (±2000 °/s), 16 bits.
- HMC5883L (Honeywell): gain 1 (±1.3 Ga, CRB = 0x20) gives 1090 LSB/gauss; outputs −2048…2047, and
  −4096 on an overflowing axis. 1 gauss = 100 µT.
"""

from __future__ import annotations

import numpy as np

STANDARD_GRAVITY_M_S2 = 9.80665

ADXL345_LSB_PER_G = 256.0
ADXL345_MIN, ADXL345_MAX = -4096, 4095  # full resolution at ±16 g: 13 bits

ITG3200_LSB_PER_DPS = 14.375
ITG3200_MIN, ITG3200_MAX = -32768, 32767

HMC5883L_LSB_PER_GAUSS = 1090.0
HMC5883L_LSB_PER_UT = HMC5883L_LSB_PER_GAUSS / 100.0
HMC5883L_MIN, HMC5883L_MAX = -2048, 2047
HMC5883L_OVERFLOW = -4096


def accel_lsb_to_g(lsb):
    return np.asarray(lsb, dtype=float) / ADXL345_LSB_PER_G


def gyro_lsb_to_dps(lsb):
    return np.asarray(lsb, dtype=float) / ITG3200_LSB_PER_DPS


def mag_lsb_to_uT(lsb):
    return np.asarray(lsb, dtype=float) / HMC5883L_LSB_PER_UT


def _quantise(x, lo, hi):
    return np.clip(np.rint(x), lo, hi).astype(np.int16)


def accel_m_s2_to_lsb(acc_m_s2):
    """Accelerometer in m/s² to ADXL345 full-resolution LSB, rounded and saturated as the chip does."""
    return _quantise(np.asarray(acc_m_s2) / STANDARD_GRAVITY_M_S2 * ADXL345_LSB_PER_G, ADXL345_MIN, ADXL345_MAX)


def gyro_rad_s_to_lsb(gyr_rad_s):
    """Angular rate in rad/s to ITG-3200 LSB, rounded and saturated."""
    return _quantise(np.degrees(np.asarray(gyr_rad_s)) * ITG3200_LSB_PER_DPS, ITG3200_MIN, ITG3200_MAX)


def mag_uT_to_lsb(mag_uT):
    """Magnetic field in µT to HMC5883L LSB at gain 1; an axis past the range reads −4096, as the chip's does."""
    x = np.rint(np.asarray(mag_uT, dtype=float) * HMC5883L_LSB_PER_UT)
    over = (x < HMC5883L_MIN) | (x > HMC5883L_MAX)
    return np.where(over, HMC5883L_OVERFLOW, x).astype(np.int16)
