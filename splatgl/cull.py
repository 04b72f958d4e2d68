"""CPU cull stage: which splats can touch the image (before the sort and the draw).

Culls on view-space z before any perspective divide (points behind the camera would mirror into
view after it), then tests a conservative bound of each splat's extent against the screen: the
sphere of radius ``k * max(scale)`` (k = the opacity-aware sigma count, at most
sqrt(2 ln 255) ~ 3.33) widened by the low-pass dilation's reach, against the four side planes
of the view frustum (an axis-aligned box for orthographic cameras).
"""

from __future__ import annotations

import numpy as np

from .camera import Camera
from .constants import ALPHA_MIN, LOW_PASS

#: Extra screen margin (pixels) so the 0.3 px^2 dilation and pixel-centre rounding never cull
#: a splat whose quad would touch the image.
MARGIN_PX = 3.33 * float(np.sqrt(LOW_PASS)) + 1.0


def cull(p_cam: np.ndarray, max_scale: np.ndarray, opacities: np.ndarray, camera: Camera,
         near: float) -> np.ndarray:
    """Boolean mask (N,) of splats to keep.

    Args:
        p_cam: (N, 3) camera-space centres (float32 or float64).
        max_scale: (N,) largest scale of each splat (world units).
        opacities: (N,) opacities; below 1/255 a splat can never be drawn.
        camera: the view.  near: view z at or below which splats are culled.
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
        return keep & (x >= u_lo - rx) & (x <= u_hi + rx) & (y >= v_lo - ry) & (y <= v_hi + ry)
    # Side planes through the camera centre: x / z = s for slopes s at the image edges.
    # The signed distance of a point from the plane x - s z = 0 is (x - s z) / sqrt(1 + s^2).
    for coord, f, c, size in ((x, camera.fx, camera.cx, camera.width),
                              (y, camera.fy, camera.cy, camera.height)):
        lo, hi = -c / f, (size - c) / f
        reach = radius + MARGIN_PX * np.maximum(z, 0.0) / f
        keep &= (coord - hi * z) / np.sqrt(1.0 + hi * hi) <= reach
        keep &= (lo * z - coord) / np.sqrt(1.0 + lo * lo) <= reach
    return keep
