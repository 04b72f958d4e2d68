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
from ..constants import PEAK_CLAMP_SIGMAS
from ..errors import CameraError
from ..scene.quaternion import quat_to_rotmat


# ``t*`` is clamped to PEAK_CLAMP_SIGMAS standard deviations of the splat's view depth about its
# centre: along a ray nearly parallel to a needle or a plane the Gaussian's peak lies far outside
# the splat (measured on guitar: t* = -3.5 for a splat at z = 5.7, with alpha 0.007 at that
# pixel), where nothing of it is seen; unclamped, such outliers sort first and no bounded re-sort
# can bring them there.


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
    """(N, 10) coefficients of ``t*`` (module doc), in ``dtype``, computed in float64:
    perspective ``(m_x, m_y, mu_z, A, B_x, B_y, Q2_xx, Q2_xy, Q2_yy, r_z)``, orthographic
    ``(mu_x, mu_y, mu_z, 0, B_x, B_y, 0, 0, 0, r_z)``, ``r_z = 3 sqrt(Sigma_zz)`` the splat's
    3-sigma half extent in view z (:func:`peak_depth` clamps ``t*`` to ``mu_z +- r_z``); zero
    rows where not ``visible``.
    (N, 3) camera-space centres, (N, 4) quaternions, (N, 3) scales (world), the (anchored) camera."""
    check_camera(camera)
    mu = np.asarray(p_cam, np.float64)
    s = np.asarray(scales, np.float64)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        inv = (np.min(s, axis=1, keepdims=True) / s) ** 2            # <= 1
        m = np.asarray(camera.rotation, np.float64) @ quat_to_rotmat(np.asarray(rotations, np.float64))
        q = (m * inv[:, None, :]) @ np.swapaxes(m, 1, 2)               # W R S^-2 R^T W^T, scaled
        out = np.zeros((len(mu), 10))
        out[:, 9] = PEAK_CLAMP_SIGMAS * np.sqrt(np.einsum("nj,nj->n", m[:, 2, :] ** 2, s ** 2))
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
    """``t*`` of splats with coefficients ``peak`` (..., 10) at rays ``(ax, ay)`` (broadcast with
    ``peak[..., 0]``), in their dtype, clamped to the splat's depth range ``mu_z +- r_z``.  A
    denominator at or below 0 (rounding, a degenerate splat) gives the centre's depth."""
    dx, dy = ax - peak[..., 0], ay - peak[..., 1]
    lin = peak[..., 4] * dx + peak[..., 5] * dy
    mu_z, r_z = peak[..., 2], peak[..., 9]
    if parallel:
        t = mu_z + lin
    else:
        a = peak[..., 3]
        den = (a + lin + lin + (peak[..., 6] * dx * dx + peak[..., 8] * dy * dy)
               + (peak[..., 7] + peak[..., 7]) * dx * dy)
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            t = np.where(den > 0, mu_z * (a + lin) / den, mu_z)
    return np.minimum(np.maximum(t, mu_z - r_z), mu_z + r_z)


#: Sort keys of the per-pixel order clamp the peak depth below at this (a positive float's bits
#: order like its value; a ray can meet a Gaussian's peak behind the camera).
MIN_KEY_DEPTH = 1e-30


def tile_key_bits(peak: np.ndarray, mean2d: np.ndarray, tile_x: np.ndarray, tile_y: np.ndarray,
                  rays: Rays, tile_size: int) -> np.ndarray:
    """(M,) uint64 float32 bits of ``max(t*, MIN_KEY_DEPTH)`` where each key's splat is nearest
    to its tile: at the splat's centre ``mean2d`` (M, 2) clamped into the box of the tile's pixel
    centres, in the dtype of ``peak`` (M, 9).  The per-pixel order's tile lists start from each
    splat's depth where it meets the tile, so that each pixel's bounded re-sort (the tile
    renderer's window) has little left to fix.  (At the tile's centre instead, a small flat
    splat off to one side gets the depth where that ray crosses its plane, anywhere.)"""
    dt = peak.dtype.type
    lo_x = (tile_x * tile_size).astype(peak.dtype) + dt(0.5)
    lo_y = (tile_y * tile_size).astype(peak.dtype) + dt(0.5)
    px = np.minimum(np.maximum(mean2d[:, 0], lo_x), lo_x + dt(tile_size - 1))
    py = np.minimum(np.maximum(mean2d[:, 1], lo_y), lo_y + dt(tile_size - 1))
    ax = (px - dt(rays.cx)) / dt(rays.fx)
    ay = (py - dt(rays.cy)) / dt(rays.fy)
    t = np.maximum(peak_depth(peak, ax, ay, rays.parallel), dt(MIN_KEY_DEPTH))
    return np.ascontiguousarray(t, np.float32).view(np.uint32).astype(np.uint64)
