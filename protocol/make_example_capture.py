#!/usr/bin/env python3
"""Writes protocol/examples/broad_fast_rotation_4s.cap: a capture as the sphere would send it, made on
the host from four seconds of BROAD trial 07 (fast rotation), for the README's first command and the
decoder tests. `python3 protocol/make_example_capture.py [--broad DIR]` remakes it byte for byte.

How it is made: the trial's gyroscope and accelerometer (285.7 Hz) are resampled linearly to the
sphere's 200 Hz clock and the magnetometer to the HMC5883L's 75 Hz (held until the next sample, with
`mag_fresh` set on the first RAW_SAMPLE after each new one); all three are converted to chip units with
the chips' sensitivities and saturation (host/sphere/chips.py). ORIENTATION at 100 Hz carries BROAD's
optical reference turned from ENU into the sphere's NWU frame — not a filter output. HELLO starts the
stream, STATUS follows once a second. BROAD: Laidig et al., Data 6(7):72, 2021, CC BY 4.0.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "host"))

from sphere import chips, quaternion  # noqa: E402
from sphere.broad import find_trial, load_trial  # noqa: E402
from sphere.protocol import Hello, Orientation, RawSample, Status, encode_frame  # noqa: E402

TRIAL, START_S, SECONDS = "07", 30.0, 4.0
IMU_HZ, MAG_HZ, ORI_HZ = 200, 75, 100
BOOT_US = 3_000_000  # the stream starts three seconds after the device's clock started
OUT = Path(__file__).resolve().parent / "examples" / "broad_fast_rotation_4s.cap"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--broad", help="BROAD folder (default: SPHERE_BROAD_DIR or ../shared/data/broad)")
    args = ap.parse_args()
    trial = load_trial(find_trial(TRIAL, args.broad))
    t_src = np.arange(len(trial)) / trial.rate_hz
    n = int(SECONDS * IMU_HZ)
    t = START_S + np.arange(n) / IMU_HZ

    def resample(x):
        return np.stack([np.interp(t, t_src, x[:, k]) for k in range(x.shape[1])], axis=1)

    gyro = chips.gyro_rad_s_to_lsb(resample(trial.gyr_rad_s))
    accel = chips.accel_m_s2_to_lsb(resample(trial.acc_m_s2))
    mag_index = np.floor((t - START_S) * MAG_HZ).astype(int)  # newest 75 Hz sample at each 200 Hz tick
    mag_t = START_S + mag_index / MAG_HZ
    mag = chips.mag_uT_to_lsb(np.stack([np.interp(mag_t, t_src, trial.mag_uT[:, k]) for k in range(3)], axis=1))
    fresh = np.r_[True, np.diff(mag_index) > 0]

    q_enu = trial.opt_quat.copy()
    finite = np.all(np.isfinite(q_enu), axis=1)
    q_enu = q_enu[np.interp(np.arange(len(q_enu)), np.flatnonzero(finite), np.flatnonzero(finite)).astype(int)]
    q_nwu = quaternion.multiply(quaternion.conjugate(quaternion.Q_NWU_TO_ENU), q_enu)
    q_at = q_nwu[np.clip(np.rint(t * trial.rate_hz).astype(int), 0, len(q_nwu) - 1)]
    q_at *= np.sign(q_at[:, :1])
    q14 = np.clip(np.rint(q_at * 16384), -32768, 32767).astype(int)

    frames, seq = [b"\x00"], 0

    def send(packet):
        nonlocal seq
        frames.append(encode_frame(packet, seq))
        seq = (seq + 1) & 0xFF

    send(Hello(1, (0, 1, 0), 7, 0xE5, 0x69, b"H43", IMU_HZ, MAG_HZ, 7, IMU_HZ, ORI_HZ, 0x21))
    for i in range(n):
        t_us = BOOT_US + i * 1_000_000 // IMU_HZ
        flags = 0x07 | (0x08 if fresh[i] else 0)
        send(RawSample(t_us, flags, tuple(int(v) for v in accel[i]), tuple(int(v) for v in gyro[i]), tuple(int(v) for v in mag[i])))
        if i % (IMU_HZ // ORI_HZ) == 0:
            send(Orientation(t_us, 0x01, tuple(int(v) for v in q14[i])))
        if i % IMU_HZ == IMU_HZ - 1:
            send(Status(t_us, 0x07, (0, 0, 0), 0, 0, 0, 0, 0x21, 0, 0, 0))
    OUT.parent.mkdir(parents=True, exist_ok=True)
    OUT.write_bytes(b"".join(frames))
    print(f"wrote {OUT}: {len(frames) - 1} frames, {OUT.stat().st_size} bytes")


if __name__ == "__main__":
    main()
