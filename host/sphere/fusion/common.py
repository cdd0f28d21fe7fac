"""Small helpers shared by the filters: the accelerometer + magnetometer orientation (e-compass)."""

from __future__ import annotations

import math

import numpy as np


def quat_from_matrix(r) -> tuple:
    """Unit quaternion (w, x, y, z) of a rotation matrix given as rows (Shepperd's method)."""
    (r00, r01, r02), (r10, r11, r12), (r20, r21, r22) = r
    tr = r00 + r11 + r22
    if tr > 0.0:
        s = 2.0 * math.sqrt(tr + 1.0)
        q = (0.25 * s, (r21 - r12) / s, (r02 - r20) / s, (r10 - r01) / s)
    elif r00 > r11 and r00 > r22:
        s = 2.0 * math.sqrt(1.0 + r00 - r11 - r22)
        q = ((r21 - r12) / s, 0.25 * s, (r01 + r10) / s, (r02 + r20) / s)
    elif r11 > r22:
        s = 2.0 * math.sqrt(1.0 + r11 - r00 - r22)
        q = ((r02 - r20) / s, (r01 + r10) / s, 0.25 * s, (r12 + r21) / s)
    else:
        s = 2.0 * math.sqrt(1.0 + r22 - r00 - r11)
        q = ((r10 - r01) / s, (r02 + r20) / s, (r12 + r21) / s, 0.25 * s)
    if q[0] < 0.0:
        q = (-q[0], -q[1], -q[2], -q[3])
    return q


def ecompass(ax, ay, az, mx, my, mz, frame: str = "NWU") -> tuple:
    """Sensor-to-earth quaternion from one accelerometer and one magnetometer sample.

    The earth z axis is along the measured specific force (up), the horizontal magnetic field points to
    earth x (NWU: north = x) or y (ENU: north = y). This is the orientation at which Madgwick's stacked
    objective f = [f_g; f_b] is exactly zero, i.e. where its gradient descent converges.
    With no usable magnetometer (None or zero) the heading is chosen so that earth x follows sensor x.
    """
    n = math.sqrt(ax * ax + ay * ay + az * az)
    ux, uy, uz = ax / n, ay / n, az / n
    if mx is None or (mx == 0.0 and my == 0.0 and mz == 0.0):
        mx, my, mz = 1.0, 0.0, 0.0
        if abs(ux) > 0.9:
            mx, my, mz = 0.0, 1.0, 0.0
    # west = up × m, north = west × up (all in sensor coordinates)
    wx, wy, wz = uy * mz - uz * my, uz * mx - ux * mz, ux * my - uy * mx
    n = math.sqrt(wx * wx + wy * wy + wz * wz)
    wx, wy, wz = wx / n, wy / n, wz / n
    nx, ny, nz = wy * uz - wz * uy, wz * ux - wx * uz, wx * uy - wy * ux
    if frame == "NWU":
        rows = ((nx, ny, nz), (wx, wy, wz), (ux, uy, uz))
    elif frame == "ENU":
        rows = ((-wx, -wy, -wz), (nx, ny, nz), (ux, uy, uz))
    else:
        raise ValueError(f"unknown earth frame {frame!r} (NWU or ENU)")
    return quat_from_matrix(rows)


def batch_inputs(gyr, acc, mag, acc_valid=None, mag_valid=None):
    """(N, 3) arrays as the per-sample lists an ``update_batch`` loop walks: gyro, accelerometer,
    magnetometer (``None`` per sample when ``mag`` is None) and the two validity flags (all True when
    not given)."""
    gyr = np.asarray(gyr, dtype=float).tolist()
    acc = np.asarray(acc, dtype=float).tolist()
    n = len(gyr)
    magl = np.asarray(mag, dtype=float).tolist() if mag is not None else [None] * n
    av = [True] * n if acc_valid is None else [bool(v) for v in acc_valid]
    mv = [True] * n if mag_valid is None else [bool(v) for v in mag_valid]
    return gyr, acc, magl, av, mv
