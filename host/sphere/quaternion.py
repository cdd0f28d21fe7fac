"""Quaternions, scalar first, [w, x, y, z], Hamilton product: the project's one definition of the product and
of the earth-frame rotation.

Two forms of the same arithmetic: :func:`mul` and :func:`conj` on one quaternion as a tuple of floats (the
per-sample paths: the daemon, the pointer smoothing, the scripted sphere, the filters), and the functions on
numpy arrays (:func:`multiply`, :func:`conjugate`, :func:`rotate` …), which accept a single quaternion of
shape (4,) or a batch of shape (N, 4). :func:`multiply` is :func:`mul` applied to the array's components, so
the product is written once.
"""

from __future__ import annotations

import math

import numpy as np

#: Rotation that turns an NWU earth frame (x north, y west, z up, the device's: protocol/spec.md §4.3) into ENU
#: (x east, y north, z up, the host filters'): q_ENU = Q_NWU_TO_ENU ⊗ q_NWU, a turn of +90° about z.
Q_NWU_TO_ENU = (math.sqrt(0.5), 0.0, 0.0, math.sqrt(0.5))


def mul(p, q) -> tuple:
    """Hamilton product p ⊗ q (seed digest eq. 24) of two quaternions given as four numbers each; the numbers
    may also be numpy arrays of equal shape (:func:`multiply` uses that)."""
    p0, p1, p2, p3 = p
    q0, q1, q2, q3 = q
    return (p0 * q0 - p1 * q1 - p2 * q2 - p3 * q3,
            p0 * q1 + p1 * q0 + p2 * q3 - p3 * q2,
            p0 * q2 - p1 * q3 + p2 * q0 + p3 * q1,
            p0 * q3 + p1 * q2 - p2 * q1 + p3 * q0)


def conj(q) -> tuple:
    """The conjugate (the inverse of a unit quaternion) of four numbers."""
    return (q[0], -q[1], -q[2], -q[3])


def multiply(p: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Hamilton product p ⊗ q of arrays of shape (4,) or (N, 4) (broadcast against each other)."""
    p = np.moveaxis(np.asarray(p, dtype=float), -1, 0)
    q = np.moveaxis(np.asarray(q, dtype=float), -1, 0)
    return np.stack(mul(p, q), axis=-1)


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
