"""Small builders for the stress scenes: splats from plain values, rotations, cameras.

Everything here builds :class:`~splatgl.scene.splats.Scene` directly (not through the loaders), so a
case can hold values the loaders would reject (zero quaternions, infinite logits).
"""

from __future__ import annotations

import numpy as np

from ...cameras.camera import Camera
from ...cameras.poses import look_at
from ...constants import SH_C0
from ...scene.splats import Scene, SplatKind

#: Image size of most cases: small (fast on llvmpipe and in NumPy) but several 16 x 16 tiles.
WIDTH, HEIGHT = 64, 48

#: Distinct colours, cycled over the splats of a case.
PALETTE = np.array([[0.9, 0.2, 0.1], [0.1, 0.8, 0.3], [0.2, 0.3, 0.95], [0.95, 0.85, 0.1],
                    [0.7, 0.2, 0.9], [0.1, 0.9, 0.9], [0.6, 0.6, 0.6]])


def splats(means, scales, quats=None, opacities=None, logits=None, rgb=None, sh_rest=None,
           kind: SplatKind = SplatKind.GAUSSIAN_3D) -> Scene:
    """A scene from activated values.

    Args:
        means: (N, 3) world positions.  scales: (N, 3) (surfels (N, 2)) standard deviations.
        quats: (N, 4) raw quaternions (default identity); stored as given.
        opacities: (N,) in [0, 1] (default 0.8), or ``logits`` (N,) stored as given.
        rgb: (N, 3) base colours (default: the palette); ``sh_rest`` (N, K - 1, 3) optional.
    """
    means = np.asarray(means, np.float64)
    n = means.shape[0]
    quats = np.tile([1.0, 0.0, 0.0, 0.0], (n, 1)) if quats is None else np.asarray(quats, np.float64)
    if logits is None:
        o = np.full(n, 0.8) if opacities is None else np.asarray(opacities, np.float64)
        with np.errstate(divide="ignore"):
            logits = np.log(o) - np.log1p(-o)
    rgb = PALETTE[np.arange(n) % len(PALETTE)] if rgb is None else np.asarray(rgb, np.float64)
    dc = ((rgb - 0.5) / SH_C0)[:, None, :]
    sh = dc if sh_rest is None else np.concatenate([dc, np.asarray(sh_rest, np.float64)], 1)
    with np.errstate(divide="ignore"):
        log_scales = np.log(np.asarray(scales, np.float64))
    return Scene(means.astype(np.float32), quats.astype(np.float32),
                 log_scales.astype(np.float32), np.asarray(logits, np.float32),
                 sh.astype(np.float32), kind)


def front_camera(distance: float = 5.0, fov_y: float = 60.0, width: int = WIDTH,
                 height: int = HEIGHT, target=(0.0, 0.0, 0.0)) -> Camera:
    """Perspective camera ``distance`` in front of ``target`` looking along world +z.

    Its camera axes equal the world axes (x right, y down), so world x, y map to u, v.
    """
    target = np.asarray(target, np.float64)
    pose = look_at(target - [0.0, 0.0, distance], target, (0.0, -1.0, 0.0))
    return Camera.from_fov(width, height, fov_y, pose)


def at_pixel(camera: Camera, u: float, v: float, z: float) -> np.ndarray:
    """(3,) world point at view depth ``z`` projecting to pixel coordinates (u, v).

    For a :func:`front_camera` (camera axes = world axes) only; orthographic cameras too.
    """
    if camera.is_orthographic:
        x, y = (u - camera.cx) / camera.fx, (v - camera.cy) / camera.fy
    else:
        x, y = (u - camera.cx) * z / camera.fx, (v - camera.cy) * z / camera.fy
    return camera.center + np.array([x, y, z])
