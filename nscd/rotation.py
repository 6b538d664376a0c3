"""Rotations: 2D angles and 3D unit quaternions (w, x, y, z), body to world."""
from __future__ import annotations

import math

import numpy as np

from nscd._jit import njit, njit_helper


def rotation_2d(angle: float) -> np.ndarray:
    """2x2 rotation matrix for a counter-clockwise ``angle`` in rad."""
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, -s], [s, c]])


def quaternion_to_matrix(quat: np.ndarray) -> np.ndarray:
    """3x3 rotation matrix (body to world) of a unit quaternion ``(w, x, y, z)``.

    ``quat`` of shape (4, ...) gives (3, 3, ...) (:func:`rotation_matrices` per quaternion).
    """
    quat = np.asarray(quat, dtype=float)
    flat = np.ascontiguousarray(quat.reshape(4, -1).T)
    return np.moveaxis(rotation_matrices(flat), 0, -1).reshape((3, 3) + quat.shape[1:])


@njit
def rotation_matrices(quats: np.ndarray) -> np.ndarray:
    """Rotation matrices (m, 3, 3), body to world, of unit quaternions ``(w, x, y, z)`` (m, 4)."""
    out = np.empty((quats.shape[0], 3, 3))
    for k in range(quats.shape[0]):
        w, x, y, z = quats[k, 0], quats[k, 1], quats[k, 2], quats[k, 3]
        out[k, 0, 0], out[k, 0, 1], out[k, 0, 2] = 1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)
        out[k, 1, 0], out[k, 1, 1], out[k, 1, 2] = 2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)
        out[k, 2, 0], out[k, 2, 1], out[k, 2, 2] = 2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)
    return out


def quaternion_multiply(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton product ``a * b`` of quaternions ``(w, x, y, z)`` (:func:`_hamilton`)."""
    return np.array(_hamilton(*(float(x) for x in a), *(float(x) for x in b)))


@njit
def _hamilton(aw, ax, ay, az, bw, bx, by, bz):
    """Hamilton product ``a * b`` of quaternions ``(w, x, y, z)`` given by their components."""
    return (aw * bw - ax * bx - ay * by - az * bz,
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw)


@njit_helper
def drift_poses(q, v, span, moving):
    """Poses (S, n_bodies, nq) after moving the bodies ``moving`` (indices) for ``span`` (S,)
    seconds at constant velocity ``v`` (S, n_bodies, nv); the other rows unchanged.

    2D (nq = 3): ``q + span v``. 3D (nq = 7): positions likewise, quaternions by the exact
    exponential map ``exp(span omega / 2) * quat`` of the world-frame rotation vector
    ``span * omega`` (rad), renormalised.
    """
    out = q.copy()
    dim = 2 if q.shape[2] == 3 else 3
    for s in range(q.shape[0]):
        h = span[s]
        for i in moving:
            for d in range(dim):
                out[s, i, d] = q[s, i, d] + h * v[s, i, d]
            if dim == 2:
                out[s, i, 2] = q[s, i, 2] + h * v[s, i, 2]
                continue
            rx, ry, rz = h * v[s, i, 3], h * v[s, i, 4], h * v[s, i, 5]
            aw, ax, ay, az = q[s, i, 3], q[s, i, 4], q[s, i, 5], q[s, i, 6]
            angle = math.sqrt(rx * rx + ry * ry + rz * rz)
            if angle >= 1e-300:
                half = 0.5 * angle
                sn = math.sin(half) / angle
                aw, ax, ay, az = _hamilton(math.cos(half), sn * rx, sn * ry, sn * rz, aw, ax, ay, az)
            norm = math.sqrt(aw * aw + ax * ax + ay * ay + az * az)
            out[s, i, 3], out[s, i, 4], out[s, i, 5], out[s, i, 6] = aw / norm, ax / norm, ay / norm, az / norm
    return out


def tilt_angle(quat0: np.ndarray, quat: np.ndarray) -> float:
    """Angle in rad between a body's vertical (z) axis at orientation ``quat0`` and at ``quat``."""
    z0 = quaternion_to_matrix(quat0)[:, 2]
    z1 = quaternion_to_matrix(quat)[:, 2]
    return float(np.arccos(np.clip(z0 @ z1, -1.0, 1.0)))
