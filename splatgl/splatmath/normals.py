"""NumPy twin of the splat normal (``shaders/lib/normal.glsl`` ``splat_normal``): the normal layer.

- 3DGS: the axis of the smallest scale, ``R[:, k]`` with ``k`` the first index of
  ``min(s_0, s_1, s_2)`` (the convention of the normal-supervised 3DGS work: a flat splat's
  normal is its thin axis);
- 2DGS surfels: the surfel's own normal ``t_u x t_v = R[:, 2]``;

rotated into camera space (``R_cw``, normalised again: a scene transform's uniform scale is
folded into ``R_cw``) and turned towards the camera: negated where ``n . d > 0`` with ``d`` the
direction from the camera to the splat's centre (its camera-space centre ``p``, the eye's for
omni-directional stereo; ``(0, 0, 1)`` for parallel rays, an orthographic camera).  The normal
layer blends these with the colour's weights (:mod:`splatgl.output.layers`).
"""

from __future__ import annotations

import numpy as np

from .project import quat_to_rotmat


def splat_normals(rotations: np.ndarray, scales: np.ndarray, p_cam: np.ndarray,
                  view_rotation: np.ndarray, parallel_rays: bool, surfel: bool) -> np.ndarray:
    """(N, 3) unit camera-space normals (module doc), in ``p_cam``'s dtype.

    Args:
        rotations: (N, 4) quaternions (w, x, y, z), any norm.  scales: (N, 3) (or (N, 2) for
            surfels; unused there) activated scales.
        p_cam: (N, 3) camera-space centres (after the omni-directional stereo eye, if any).
        view_rotation: (3, 3) the world-to-camera rotation the splats are drawn with.
        parallel_rays: every ray points along +z (orthographic).  surfel: 2DGS surfels.
    """
    dt = p_cam.dtype
    rot = quat_to_rotmat(np.asarray(rotations, dt))
    if surfel:
        axis = rot[:, :, 2]
    else:
        s = np.asarray(scales, dt)
        k = np.argmin(s[:, :3], axis=1)              # the first of equal smallest scales
        axis = np.take_along_axis(rot, k[:, None, None], axis=2)[:, :, 0]
    n = axis @ np.asarray(view_rotation, dt).T       # R_cw axis, row-vector form
    n = n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), dt.type(1e-30))
    towards = np.broadcast_to(np.array([0.0, 0.0, 1.0], dt), p_cam.shape) if parallel_rays else p_cam
    flip = (n * towards).sum(axis=1) > 0
    return np.where(flip[:, None], -n, n).astype(dt)
