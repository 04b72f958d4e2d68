"""Quaternions ``(w, x, y, z)`` in one place: products, rotation matrices both ways, log and
exp.  Every function takes arrays whose last axis holds the four components (``(4,)`` or
``(..., 4)``; matrices ``(..., 3, 3)``) and works in the dtype it is given.

Used by the projection (splat rotations), the level-of-detail builder (parents' principal axes
back to quaternions), the camera paths (squad interpolation), COLMAP and glTF readers, and the
stress cases.  The smallest-three encoding (and the rotation error its quantisation implies) is
here too: the lossy writers (:mod:`splatgl.formats.quantise`) and the compact GPU layout
(:mod:`splatgl.gl.storage`) share it.
"""

from __future__ import annotations

import math

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


def half_step_rotation_deg(component_error: float) -> float:
    """Bound (degrees) on the rotation error of a smallest-three quaternion whose three stored
    components are each off by at most ``component_error``.

    The three stored components move by at most ``sqrt(3) e``; the largest component (at least
    1/2) is recomputed as ``sqrt(1 - r^2)`` with ``r <= sqrt(3)/2``, whose slope ``r / L`` is at
    most ``sqrt(3)``, so the unit quaternion moves by a chord of at most ``2 sqrt(3) e``.  Two
    unit quaternions a chord ``c`` apart differ by a rotation of ``4 asin(c / 2)``.  A 5% margin
    covers the first-order slope estimate.
    """
    chord = 1.05 * 2.0 * math.sqrt(3.0) * component_error
    return math.degrees(4.0 * math.asin(min(1.0, chord / 2.0)))


def smallest_three(q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unit quaternions ``q`` (N, 4) in any component order -> ``(largest index (N,) intp,
    the other three (N, 3) float64 in index order)``, sign-flipped so the largest is >= 0."""
    q = np.asarray(q, np.float64)
    q = q / np.linalg.norm(q, axis=1, keepdims=True)
    largest = np.argmax(np.abs(q), axis=1)
    rows = np.arange(q.shape[0])
    q = q * np.where(q[rows, largest] < 0.0, -1.0, 1.0)[:, None]
    keep = np.ones_like(q, bool)
    keep[rows, largest] = False
    return largest, q[keep].reshape(-1, 3)
