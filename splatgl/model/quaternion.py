"""Quaternions ``(w, x, y, z)`` in one place: products, rotation matrices both ways, log and
exp.  Every function takes arrays whose last axis holds the four components (``(4,)`` or
``(..., 4)``; matrices ``(..., 3, 3)``) and works in the dtype it is given.

Used by the projection (splat rotations), the level-of-detail builder (parents' principal axes
back to quaternions), the camera paths (squad interpolation), COLMAP and glTF readers, and the
stress cases.
"""

from __future__ import annotations

import numpy as np


def quat_to_rotmat(q: np.ndarray) -> np.ndarray:
    """(..., 4) quaternions (w, x, y, z), any norm -> (..., 3, 3) rotation matrices (normalised)."""
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    w, x, y, z = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    r = np.empty(q.shape[:-1] + (3, 3), q.dtype)
    r[..., 0, 0] = 1 - 2 * (y * y + z * z)
    r[..., 0, 1] = 2 * (x * y - w * z)
    r[..., 0, 2] = 2 * (x * z + w * y)
    r[..., 1, 0] = 2 * (x * y + w * z)
    r[..., 1, 1] = 1 - 2 * (x * x + z * z)
    r[..., 1, 2] = 2 * (y * z - w * x)
    r[..., 2, 0] = 2 * (x * z - w * y)
    r[..., 2, 1] = 2 * (y * z + w * x)
    r[..., 2, 2] = 1 - 2 * (x * x + y * y)
    return r


def rotmat_to_quat(r: np.ndarray) -> np.ndarray:
    """(..., 3, 3) proper rotations -> (..., 4) float64 unit quaternions with w >= 0.

    Shepperd's method: the largest of ``trace, r00, r11, r22`` picks the pivot component, so no
    division comes near zero.
    """
    r = np.asarray(r, np.float64)
    shape = r.shape[:-2]
    m = r.reshape(-1, 3, 3)
    t = np.stack([m[:, 0, 0] + m[:, 1, 1] + m[:, 2, 2], m[:, 0, 0], m[:, 1, 1], m[:, 2, 2]], 1)
    pick = np.argmax(t, axis=1)
    q = np.empty((m.shape[0], 4))
    s = pick == 0
    w = 0.5 * np.sqrt(np.maximum(1.0 + t[s, 0], 1e-300))
    q[s] = np.stack([w, (m[s, 2, 1] - m[s, 1, 2]) / (4 * w), (m[s, 0, 2] - m[s, 2, 0]) / (4 * w),
                     (m[s, 1, 0] - m[s, 0, 1]) / (4 * w)], 1)
    for axis in range(3):
        s = pick == axis + 1
        i, j, k = axis, (axis + 1) % 3, (axis + 2) % 3
        x = 0.5 * np.sqrt(np.maximum(1.0 + m[s, i, i] - m[s, j, j] - m[s, k, k], 1e-300))
        out = np.empty((int(s.sum()), 4))
        out[:, 0] = (m[s, k, j] - m[s, j, k]) / (4 * x)
        out[:, 1 + i] = x
        out[:, 1 + j] = (m[s, j, i] + m[s, i, j]) / (4 * x)
        out[:, 1 + k] = (m[s, k, i] + m[s, i, k]) / (4 * x)
        q[s] = out
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    q[q[:, 0] < 0] *= -1.0
    return q.reshape(shape + (4,))


def quat_multiply(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton product ``a b`` (rotate by b, then by a), broadcasting over leading axes."""
    a, b = np.asarray(a), np.asarray(b)
    aw, ax, ay, az = (a[..., i] for i in range(4))
    bw, bx, by, bz = (b[..., i] for i in range(4))
    return np.stack([aw * bw - ax * bx - ay * by - az * bz, aw * bx + ax * bw + ay * bz - az * by,
                     aw * by - ax * bz + ay * bw + az * bx, aw * bz + ax * by - ay * bx + az * bw],
                    axis=-1)


def quat_conjugate(q: np.ndarray) -> np.ndarray:
    """``(w, -x, -y, -z)``: the inverse of a unit quaternion."""
    q = np.asarray(q)
    return np.concatenate([q[..., :1], -q[..., 1:]], axis=-1)


def quat_log(q: np.ndarray) -> np.ndarray:
    """(4,) pure-quaternion log (w = 0) of a unit quaternion."""
    v = q[1:]
    n = np.linalg.norm(v)
    if n < 1e-12:
        return np.zeros(4)
    return np.concatenate([[0.0], v / n * np.arctan2(n, q[0])])


def quat_exp(q: np.ndarray) -> np.ndarray:
    """(4,) exp of a pure quaternion (w ignored): a unit quaternion."""
    v = q[1:]
    n = np.linalg.norm(v)
    if n < 1e-12:
        return np.array([1.0, 0.0, 0.0, 0.0])
    return np.concatenate([[np.cos(n)], v / n * np.sin(n)])


def quat_axis_angle(axis, degrees: float) -> np.ndarray:
    """(4,) unit quaternion of a rotation by ``degrees`` about ``axis`` (any length)."""
    a = np.asarray(axis, np.float64)
    a = a / np.linalg.norm(a)
    h = np.radians(degrees) / 2.0
    return np.concatenate([[np.cos(h)], np.sin(h) * a])
