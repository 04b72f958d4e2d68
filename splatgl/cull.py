"""CPU cull stage: which splats can touch the image (before the sort and the draw).

Culls on view-space z before any perspective divide (points behind the camera would mirror into
view after it), then tests a conservative bound of each splat's extent against the screen: the
sphere of radius ``k * max(scale)`` (k = the opacity-aware sigma count, at most
sqrt(2 ln 255) ~ 3.33) widened by the low-pass dilation's reach, against the four side planes
of the view frustum (an axis-aligned box for orthographic cameras).  Splats with opacity below
1/255 go, and so do splats whose alpha cannot reach 1/255 at any pixel centre
(:func:`peak_alpha_bound`): tiny splats between pixel centres, and with antialiasing every
splat whose compensation factor pushes it under the cut.
"""

from __future__ import annotations

import numpy as np

from .camera import Camera
from .constants import AA_MIN_FACTOR, ALPHA_MIN, JACOBIAN_CLAMP, LOW_PASS

#: Extra screen margin (pixels) so the 0.3 px^2 dilation and pixel-centre rounding never cull
#: a splat whose quad would touch the image.
MARGIN_PX = 3.33 * float(np.sqrt(LOW_PASS)) + 1.0


def peak_alpha_bound(p_cam: np.ndarray, max_scale: np.ndarray, opacities: np.ndarray,
                     camera: Camera, antialias: bool = False) -> np.ndarray:
    """(N,) upper bound of the largest alpha a splat reaches at any pixel centre of the image.

    With ``d`` the distance from the projected centre to the nearest pixel centre inside the
    image, ``d^T Q d >= |d|^2 / lambda_max`` for the conic Q, and
    ``lambda_max <= ||J||_F^2 max_scale^2 + LOW_PASS`` (``||W||_2 = 1``; J the clamped EWA
    Jacobian).  So ``alpha <= o * aa * exp(-|d|^2 / (2 lambda_bound))``, where with
    antialiasing ``aa = sqrt(det / det_dilated) <= 1 - LOW_PASS / lambda_bound`` (each
    eigenvalue's factor (l - 0.3) / l grows with l), floored like the reference's factor.
    Only valid for splats in front of the camera (z > 0).
    """
    x, y, z = (p_cam[:, i].astype(np.float64) for i in range(3))
    if camera.is_orthographic:
        jf2 = np.full_like(z, camera.fx ** 2 + camera.fy ** 2)
        u, v = camera.fx * x + camera.cx, camera.fy * y + camera.cy
    else:
        zs = np.where(z > 0, z, 1.0)
        tx, ty = camera.tan_half_fov
        xc = np.clip(x / zs, -JACOBIAN_CLAMP * tx, JACOBIAN_CLAMP * tx)
        yc = np.clip(y / zs, -JACOBIAN_CLAMP * ty, JACOBIAN_CLAMP * ty)
        jf2 = (camera.fx ** 2 * (1 + xc * xc) + camera.fy ** 2 * (1 + yc * yc)) / (zs * zs)
        u, v = camera.fx * x / zs + camera.cx, camera.fy * y / zs + camera.cy
    lam = jf2 * max_scale.astype(np.float64) ** 2 + LOW_PASS
    # nearest pixel centre inside the image: (clip(round(u - 0.5), 0, W - 1) + 0.5, ...)
    with np.errstate(invalid="ignore"):
        nu = np.clip(np.round(u - 0.5), 0, camera.width - 1) + 0.5
        nv = np.clip(np.round(v - 0.5), 0, camera.height - 1) + 0.5
        d2 = (u - nu) ** 2 + (v - nv) ** 2
        bound = opacities.astype(np.float64) * np.exp(-0.5 * d2 / lam)
    if antialias:
        bound *= np.maximum(1.0 - LOW_PASS / lam, np.sqrt(AA_MIN_FACTOR))
    return np.where(np.isfinite(bound), bound, 1.0)  # never cull on a non-finite bound


def cull(p_cam: np.ndarray, max_scale: np.ndarray, opacities: np.ndarray, camera: Camera,
         near: float, antialias: bool = False) -> np.ndarray:
    """Boolean mask (N,) of splats to keep.

    Args:
        p_cam: (N, 3) camera-space centres (float32 or float64).
        max_scale: (N,) largest scale of each splat (world units).
        opacities: (N,) opacities; below 1/255 a splat can never be drawn.
        camera: the view.  near: view z at or below which splats are culled.
        antialias: whether the opacity compensation applies (tightens the peak bound).
    """
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        k = np.sqrt(np.maximum(2.0 * np.log(np.maximum(opacities, 1e-30) / ALPHA_MIN), 0.0))
    radius = (k * max_scale).astype(np.float64)
    x, y, z = (p_cam[:, i].astype(np.float64) for i in range(3))
    keep = (z > near) & (opacities >= ALPHA_MIN)
    if camera.is_orthographic:
        rx = radius + MARGIN_PX / camera.fx
        ry = radius + MARGIN_PX / camera.fy
        u_lo, u_hi = -camera.cx / camera.fx, (camera.width - camera.cx) / camera.fx
        v_lo, v_hi = -camera.cy / camera.fy, (camera.height - camera.cy) / camera.fy
        keep &= (x >= u_lo - rx) & (x <= u_hi + rx) & (y >= v_lo - ry) & (y <= v_hi + ry)
        return _peak_cull(keep, p_cam, max_scale, opacities, camera, antialias)
    # Side planes through the camera centre: x / z = s for slopes s at the image edges.
    # The signed distance of a point from the plane x - s z = 0 is (x - s z) / sqrt(1 + s^2).
    for coord, f, c, size in ((x, camera.fx, camera.cx, camera.width),
                              (y, camera.fy, camera.cy, camera.height)):
        lo, hi = -c / f, (size - c) / f
        reach = radius + MARGIN_PX * np.maximum(z, 0.0) / f
        keep &= (coord - hi * z) / np.sqrt(1.0 + hi * hi) <= reach
        keep &= (lo * z - coord) / np.sqrt(1.0 + lo * lo) <= reach
    return _peak_cull(keep, p_cam, max_scale, opacities, camera, antialias)


def _peak_cull(keep, p_cam, max_scale, opacities, camera, antialias) -> np.ndarray:
    """``keep`` minus the splats that cannot reach 1/255 at any pixel (bound on survivors only)."""
    idx = np.flatnonzero(keep)
    bound = peak_alpha_bound(p_cam[idx], max_scale[idx], opacities[idx], camera, antialias)
    keep[idx[bound < ALPHA_MIN]] = False
    return keep
