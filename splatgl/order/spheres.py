"""Bounding spheres of consecutive row ranges (the chunked cull's chunks and groups) and their
per-view test: which ranges a perspective camera keeps whole, which it drops whole.

Per view, in float64 over the spheres only (:meth:`Spheres.classify`):

- a range whose centre sphere lies beyond the near plane and strictly inside the four side
  planes of the image (both with a float32 rounding margin, :data:`ROUNDING`) and that holds no
  faint splat is accepted: every splat of it is kept with no per-splat test;
- a range wholly behind the near plane, or wholly outside one side plane widened by the screen
  margin and its largest reach, is rejected without touching its splats;
- the rest are left to the per-splat cull (:func:`splatgl.order.cull.cull_visible`).

The compiled pass (:mod:`splatgl.order._numba_cull`) runs the same tests on :attr:`Spheres.packed`
with :func:`sphere_constants`.
"""

from __future__ import annotations

import numpy as np

from ..cameras.camera import Camera
from ..cameras.view import frustum_of
from .cull import MARGIN_PX

#: Relative float32 rounding margin of the chunk tests: a chunk is accepted or rejected only
#: when its splats' float32 depths and plane tests cannot fall on the other side (the per-splat
#: float32 values are within a few ulp, 6e-8, of the exact ones; this is 1000x that).
ROUNDING = 1e-4


class Spheres:
    """Bounding spheres of consecutive row ranges: ``centre`` (C, 3) float64, ``r_centre`` (C,)
    float64 (largest distance of a splat centre from ``centre``), ``r_max`` (C,) float64
    (largest splat reach, ``CullData.radius``), ``plain`` (C,) bool (no faint splat)."""

    def __init__(self, centre, r_centre, r_max, plain):
        self.centre, self.r_centre, self.r_max, self.plain = centre, r_centre, r_max, plain

    def take(self, ids: np.ndarray) -> "Spheres":
        return Spheres(self.centre[ids], self.r_centre[ids], self.r_max[ids], self.plain[ids])

    @property
    def packed(self) -> np.ndarray:
        """(C, 6) float64 rows ``centre x, y, z, r_centre, r_max, plain`` (the compiled pass's
        input; built on first use)."""
        if getattr(self, "_packed", None) is None:
            self._packed = np.column_stack([self.centre, self.r_centre, self.r_max,
                                            self.plain]).astype(np.float64)
        return self._packed

    def classify(self, camera: Camera, near: float, scale: float = 1.0
                 ) -> tuple[np.ndarray, np.ndarray]:
        """``(accept, reject)`` (C,) bool for a perspective ``camera`` anchored to the rows'
        frame (float64; the tests are in the module doc): accept, every splat is kept with no
        per-splat test; reject, none is."""
        rot, t = camera.rotation, camera.translation
        cam = self.centre @ rot.T + t                       # (C, 3) centres, camera space
        view, sides = sphere_constants(camera, near, scale)
        s, _, t_norm, _, _ = view
        rc = self.r_centre * s
        reach = self.r_max * scale
        slack = ROUNDING * (np.linalg.norm(cam, axis=1) + rc + s * np.linalg.norm(self.centre, axis=1)
                            + t_norm)
        x, y, z = cam[:, 0], cam[:, 1], cam[:, 2]
        accept = self.plain & (z - rc > near + slack)
        reject = z + rc < near - slack
        for coord, (hi, lo, n_hi, n_lo, a_hi, a_lo, h_hi, h_lo) in ((x, sides[0]), (y, sides[1])):
            # centres strictly inside the image's pyramid: every plane test and the peak
            # bound (centre inside the image, not faint) keep the splat
            accept &= (coord - hi * z) / n_hi < -(rc + slack)
            accept &= (lo * z - coord) / n_lo < -(rc + slack)
            # every splat beyond a side plane widened by the screen margin and its reach:
            # x - a z > n r for all splats, with a = s + n m / f (cull_visible's rearranged test)
            reject |= coord - a_hi * z - rc * h_hi > n_hi * reach + slack * h_hi
            reject |= a_lo * z - coord - rc * h_lo > n_lo * reach + slack * h_lo
        return accept & ~reject, reject


def sphere_constants(camera: Camera, near: float, scale: float) -> tuple[np.ndarray, np.ndarray]:
    """Per-view constants of :meth:`Spheres.classify` (float64): ``view = (s, near, |t|,
    scale, ROUNDING)`` with ``s`` the camera-space length of a world unit, and ``sides`` (2, 8),
    per image axis ``hi, lo`` (the image edges' slopes, :func:`splatgl.cameras.view.frustum_of`),
    ``n_hi, n_lo`` (``sqrt(1 + slope^2)``, :attr:`~splatgl.cameras.view.Frustum.sides`),
    ``a_hi, a_lo`` (the slopes widened by the screen margin) and ``hypot(1, a)`` of those."""
    s = float(np.linalg.norm(camera.rotation, axis=1).max())
    view = np.array([s, near, float(np.linalg.norm(camera.translation)), scale, ROUNDING],
                    np.float64)
    sides = np.empty((2, 8), np.float64)
    frustum = frustum_of(camera)
    for axis, ((f, _lo, _hi), (lo, n_lo, hi, n_hi)) in enumerate(zip(frustum.edges, frustum.sides)):
        a_hi, a_lo = hi + n_hi * MARGIN_PX / f, lo - n_lo * MARGIN_PX / f
        sides[axis] = hi, lo, n_hi, n_lo, a_hi, a_lo, np.hypot(1.0, a_hi), np.hypot(1.0, a_lo)
    return view, sides
