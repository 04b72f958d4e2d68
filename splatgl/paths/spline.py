"""Smooth interpolation of camera keyframes: positions by a C1 Catmull-Rom (Hermite) spline,
rotations by quaternion squad (or slerp), field of view linearly.

Times are strictly increasing floats (any unit).  With ``loop`` the keyframes close into a
cycle: the segment from the last key back to the first lasts as long as the first segment.
Quaternions are ``(w, x, y, z)`` unit quaternions of camera-to-world rotations.
"""

from __future__ import annotations

import numpy as np

from ..scene.quaternion import (quat_conjugate, quat_exp, quat_log, quat_multiply, quat_to_rotmat,
                                rotmat_to_quat)


def slerp(a: np.ndarray, b: np.ndarray, t: float) -> np.ndarray:
    """Spherical linear interpolation along the shorter arc; exact ``a`` at t = 0."""
    d = float(a @ b)
    if d < 0.0:
        b, d = -b, -d
    if d > 0.9995:  # nearly equal: normalised lerp avoids dividing by sin(~0)
        q = a + t * (b - a)
        return q / np.linalg.norm(q)
    theta = np.arccos(min(d, 1.0))
    return (np.sin((1.0 - t) * theta) * a + np.sin(t * theta) * b) / np.sin(theta)


def _same_hemisphere(quats: np.ndarray) -> np.ndarray:
    out = quats.copy()
    for k in range(1, len(out)):
        if out[k] @ out[k - 1] < 0.0:
            out[k] = -out[k]
    return out


def squad_controls(quats: np.ndarray, loop: bool) -> np.ndarray:
    """Shoemake's inner control quaternions ``s_i = q_i exp(-(log(q_i^-1 q_{i+1}) +
    log(q_i^-1 q_{i-1})) / 4)``; end keys (without ``loop``) use themselves as neighbours."""
    n = len(quats)
    s = np.empty_like(quats)
    for i in range(n):
        prev = quats[(i - 1) % n] if loop or i > 0 else quats[i]
        nxt = quats[(i + 1) % n] if loop or i < n - 1 else quats[i]
        inv = quat_conjugate(quats[i])
        a, b = quat_multiply(inv, nxt), quat_multiply(inv, prev)
        a, b = (a if a[0] >= 0 else -a), (b if b[0] >= 0 else -b)
        s[i] = quat_multiply(quats[i], quat_exp(-0.25 * (quat_log(a) + quat_log(b))))
    return s


# ----------------------------------------------------------------------------- sampling
def _tangents(points: np.ndarray, times: np.ndarray, loop: bool, period: float) -> np.ndarray:
    """Catmull-Rom tangents ``m_k = (p_{k+1} - p_{k-1}) / (t_{k+1} - t_{k-1})`` (per unit time);
    one-sided at open ends."""
    n = len(points)
    m = np.zeros_like(points)
    for k in range(n):
        if loop:
            tp = times[k - 1] - (period if k == 0 else 0.0)
            tn = times[(k + 1) % n] + (period if k == n - 1 else 0.0)
            m[k] = (points[(k + 1) % n] - points[k - 1]) / (tn - tp)
        elif n == 1:
            m[k] = 0.0
        elif k == 0:
            m[k] = (points[1] - points[0]) / (times[1] - times[0])
        elif k == n - 1:
            m[k] = (points[-1] - points[-2]) / (times[-1] - times[-2])
        else:
            m[k] = (points[k + 1] - points[k - 1]) / (times[k + 1] - times[k - 1])
    return m


def _segment(t: float, times: np.ndarray, loop: bool, period: float) -> tuple[int, int, float, float]:
    """(k, k + 1 (wrapped), local parameter in [0, 1), segment length) of time ``t``."""
    n = len(times)
    if loop:
        t = times[0] + (t - times[0]) % period
    k = int(np.searchsorted(times, t, side="right") - 1)
    k = min(max(k, 0), n - 1)
    if not loop and k == n - 1:
        return k, k, 0.0, 1.0
    end = times[k + 1] if k + 1 < n else times[0] + period
    h = end - times[k]
    return k, (k + 1) % n, (t - times[k]) / h, h


def sample_poses(camera_to_world: np.ndarray, fovs: np.ndarray, times: np.ndarray,
                 samples: np.ndarray, loop: bool = False, rotation: str = "squad"):
    """Interpolate keyframes at ``samples``.

    Args:
        camera_to_world: (K, 4, 4) keyframe poses (rigid, OpenCV camera axes).
        fovs: (K,) vertical fields of view, degrees.
        times: (K,) strictly increasing keyframe times.
        samples: (N,) times to evaluate (clamped to the keyframes' range without ``loop``).
        loop: close the path (the segment after the last key returns to the first, lasting as
            long as the first segment).
        rotation: ``"squad"`` (C1 across keys) or ``"slerp"`` (piecewise, C0).

    Returns:
        ((N, 4, 4) camera-to-world, (N,) fov).  A sample exactly at a key's time returns that
        key's own matrix and fov, bit for bit.
    """
    c2w = np.asarray(camera_to_world, np.float64)
    times = np.asarray(times, np.float64)
    k_count = len(c2w)
    period = (times[-1] - times[0]) + (times[1] - times[0] if k_count > 1 else 1.0)
    pos = c2w[:, :3, 3]
    tang = _tangents(pos, times, loop, period)
    quats = _same_hemisphere(rotmat_to_quat(np.asarray(c2w)[:, :3, :3]))
    ctrl = squad_controls(quats, loop) if rotation == "squad" else quats
    out_m = np.empty((len(samples), 4, 4))
    out_f = np.empty(len(samples))
    for i, t in enumerate(np.asarray(samples, np.float64)):
        if not loop:
            t = min(max(t, times[0]), times[-1])
        k, k1, u, h = _segment(t, times, loop, period)
        if u == 0.0:
            out_m[i], out_f[i] = c2w[k], fovs[k]
            continue
        u2, u3 = u * u, u * u * u
        h00, h10, h01, h11 = 2 * u3 - 3 * u2 + 1, u3 - 2 * u2 + u, -2 * u3 + 3 * u2, u3 - u2
        p = h00 * pos[k] + h10 * h * tang[k] + h01 * pos[k1] + h11 * h * tang[k1]
        q1 = quats[k1] if quats[k] @ quats[k1] >= 0 else -quats[k1]
        q = slerp(quats[k], q1, u)
        if rotation == "squad":
            q = slerp(q, slerp(ctrl[k], ctrl[k1], u), 2.0 * u * (1.0 - u))
        m = np.eye(4)
        m[:3, :3], m[:3, 3] = quat_to_rotmat(q), p
        out_m[i], out_f[i] = m, (1.0 - u) * fovs[k] + u * fovs[k1]
    return out_m, out_f
