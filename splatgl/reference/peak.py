"""The depth at which a splat's Gaussian peaks along a pixel's ray: the key of the per-pixel
order (:mod:`splatgl.reference.per_pixel` has the derivation).  Used by the reference's
``project`` stage and its per-pixel rasterizer; the tile renderer's twin is
``shaders/lib/peak_depth.glsl``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..cameras.camera import Camera
from ..cameras.orthographic import Orthographic
from ..cameras.pinhole import Pinhole
from ..errors import CameraError
from ..model.quaternion import quat_to_rotmat


@dataclass(frozen=True)
class Rays:
    """The pixel rays of a perspective or orthographic camera: ``a = ((x - cx) / fx,
    (y - cy) / fy)`` at pixel centre (x, y); ``parallel`` for orthographic cameras."""

    cx: float
    cy: float
    fx: float
    fy: float
    parallel: bool

    @classmethod
    def of(cls, camera: Camera) -> "Rays":
        check_camera(camera)
        return cls(camera.cx, camera.cy, camera.fx, camera.fy, isinstance(camera.model, Orthographic))


def check_camera(camera: Camera) -> None:
    """The per-pixel order follows perspective and orthographic rays only."""
    if not isinstance(camera.model, (Pinhole, Orthographic)):
        raise CameraError(f"--order per-pixel draws perspective and orthographic cameras, not "
                          f"{camera.model.name} (use --order global)")


def peak_coefficients(p_cam: np.ndarray, rotations: np.ndarray, scales: np.ndarray,
                      camera: Camera, visible: np.ndarray, dtype) -> np.ndarray:
    """(N, 9) coefficients of ``t*`` (module doc), in ``dtype``, computed in float64: perspective
    ``(m_x, m_y, mu_z, A, B_x, B_y, Q2_xx, Q2_xy, Q2_yy)``, orthographic
    ``(mu_x, mu_y, mu_z, 0, B_x, B_y, 0, 0, 0)``; zero rows where not ``visible``.
    (N, 3) camera-space centres, (N, 4) quaternions, (N, 3) scales (world), the (anchored) camera."""
    check_camera(camera)
    mu = np.asarray(p_cam, np.float64)
    s = np.asarray(scales, np.float64)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        inv = (np.min(s, axis=1, keepdims=True) / s) ** 2            # <= 1
        m = np.asarray(camera.rotation, np.float64) @ quat_to_rotmat(np.asarray(rotations, np.float64))
        q = (m * inv[:, None, :]) @ np.swapaxes(m, 1, 2)               # W R S^-2 R^T W^T, scaled
        out = np.zeros((len(mu), 9))
        if isinstance(camera.model, Orthographic):
            out[:, 0:3] = mu
            out[:, 4] = -q[:, 2, 0] / q[:, 2, 2]
            out[:, 5] = -q[:, 2, 1] / q[:, 2, 2]
        else:
            c = np.concatenate([mu[:, :2] / mu[:, 2:3], np.ones((len(mu), 1))], 1)
            qc = np.einsum("nij,nj->ni", q, c)
            out[:, 0:2] = c[:, :2]
            out[:, 2] = mu[:, 2]
            out[:, 3] = np.einsum("ni,ni->n", c, qc)
            out[:, 4:6] = qc[:, :2]
            out[:, 6], out[:, 7], out[:, 8] = q[:, 0, 0], q[:, 0, 1], q[:, 1, 1]
    out = np.where((visible & np.isfinite(out).all(1))[:, None], out, 0.0)
    return out.astype(dtype)


def peak_depth(peak: np.ndarray, ax: np.ndarray, ay: np.ndarray, parallel: bool) -> np.ndarray:
    """``t*`` of splats with coefficients ``peak`` (..., 9) at rays ``(ax, ay)`` (broadcast with
    ``peak[..., 0]``), in their dtype.  A denominator at or below 0 (rounding, a degenerate
    splat) gives the centre's depth."""
    dx, dy = ax - peak[..., 0], ay - peak[..., 1]
    lin = peak[..., 4] * dx + peak[..., 5] * dy
    if parallel:
        return peak[..., 2] + lin
    a = peak[..., 3]
    den = a + lin + lin + (peak[..., 6] * dx * dx + peak[..., 8] * dy * dy) + (peak[..., 7] + peak[..., 7]) * dx * dy
    with np.errstate(divide="ignore", invalid="ignore"):
        t = peak[..., 2] * (a + lin) / den
    return np.where(den > 0, t, peak[..., 2])
