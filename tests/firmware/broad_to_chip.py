"""Convert the BROAD trials to the sphere's chip units for the firmware's native tests.

Writes one binary file per trial into the output folder: a 16-byte header
(b"SPHBROAD", uint32 LE sample period in µs, uint32 LE sample count) followed by count records of
nine little-endian int16: accel (ADXL345 LSB, 256/g), gyro (ITG-3200 LSB, 14.375 per °/s),
mag (HMC5883L LSB, 1090 per gauss), converted with host/sphere/chips.py.

Usage: python3 broad_to_chip.py OUTDIR   (data from SPHERE_BROAD_DIR, default ../shared/data/broad)
Exit status 0 with "skip: …" on stdout when the trials or the host package are not available.
"""

from __future__ import annotations

import struct
import sys
from pathlib import Path


def main() -> int:
    out = Path(sys.argv[1])
    try:
        import numpy as np

        from sphere import broad, chips
    except ImportError as e:  # host package or numpy/scipy missing
        print(f"skip: cannot import the host package ({e}); pip install -e . first")
        return 0
    try:
        paths = broad.trial_paths()
    except broad.BroadMissing as e:
        print(f"skip: {e}")
        return 0
    out.mkdir(parents=True, exist_ok=True)
    for p in paths:
        dst = out / (p.stem + ".bin")
        if dst.exists() and dst.stat().st_mtime >= p.stat().st_mtime:
            continue
        t = broad.load_trial(p)
        dt_us = int(round(1e6 / t.rate_hz))
        acc = chips.accel_m_s2_to_lsb(np.nan_to_num(t.acc_m_s2))
        gyr = chips.gyro_rad_s_to_lsb(np.nan_to_num(t.gyr_rad_s))
        mag = chips.mag_uT_to_lsb(np.nan_to_num(t.mag_uT))
        rec = np.hstack([acc, gyr, mag]).astype("<i2")
        tmp = dst.with_suffix(".tmp")
        with open(tmp, "wb") as f:
            f.write(b"SPHBROAD" + struct.pack("<II", dt_us, len(rec)))
            f.write(rec.tobytes())
        tmp.replace(dst)
        print(f"converted {p.name}: {len(rec)} samples at {t.rate_hz:.3f} Hz")
    return 0


if __name__ == "__main__":
    sys.exit(main())
