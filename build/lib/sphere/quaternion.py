"""Quaternion arithmetic on numpy arrays; scalar first, [w, x, y, z], Hamilton product.

Every function accepts a single quaternion of shape (4,) or a batch of shape (N, 4).
"""

from __future__ import annotations

import numpy as np

#: Rotation that turns an NWU earth frame (x north, y west, z up) into ENU: q_ENU = Q_NWU_TO_ENU ⊗ q_NWU.
Q_NWU_TO_ENU = np.array([np.sqrt(0.5), 0.0, 0.0, np.sqrt(0.5)])


def multiply(p: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Hamilton product p ⊗ q (seed digest eq. 24)."""
    p = np.asarray(p, dtype=float)
    q = np.asarray(q, dtype=float)
    p0, p1, p2, p3 = np.moveaxis(p, -1, 0)
    q0, q1, q2, q3 = np.moveaxis(q, -1, 0)
    return np.stack(
        [
            p0 * q0 - p1 * q1 - p2 * q2 - p3 * q3,
            p0 * q1 + p1 * q0 + p2 * q3 - p3 * q2,
            p0 * q2 - p1 * q3 + p2 * q0 + p3 * q1,
            p0 * q3 + p1 * q2 - p2 * q1 + p3 * q0,
        ],
        axis=-1,
    )


def conjugate(q: np.ndarray) -> np.ndarray:
    q = np.asarray(q, dtype=float)
    return q * np.array([1.0, -1.0, -1.0, -1.0])


def normalize(q: np.ndarray) -> np.ndarray:
    q = np.asarray(q, dtype=float)
    return q / np.linalg.norm(q, axis=-1, keepdims=True)


def rotate(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Rotate vector(s) v by q: the vector part of q ⊗ [0, v] ⊗ q*."""
    v = np.asarray(v, dtype=float)
    vq = np.concatenate([np.zeros(v.shape[:-1] + (1,)), v], axis=-1)
    return multiply(multiply(q, vq), conjugate(q))[..., 1:]


def from_axis_angle(axis: np.ndarray, angle_rad: float | np.ndarray) -> np.ndarray:
    axis = np.asarray(axis, dtype=float)
    axis = axis / np.linalg.norm(axis, axis=-1, keepdims=True)
    half = np.asarray(angle_rad, dtype=float)[..., None] / 2.0
    return np.concatenate([np.cos(half), np.sin(half) * axis], axis=-1)


def nwu_to_enu(q_nwu: np.ndarray) -> np.ndarray:
    """Sensor-to-NWU orientation(s) expressed as sensor-to-ENU."""
    return multiply(Q_NWU_TO_ENU, q_nwu)


def angle_between_deg(p: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Smallest rotation angle between orientations p and q, in degrees."""
    d = np.abs(np.sum(normalize(p) * normalize(q), axis=-1))
    return np.degrees(2.0 * np.arccos(np.clip(d, 0.0, 1.0)))
