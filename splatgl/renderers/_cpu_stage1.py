"""The CPU renderer's stage 1 (projection) on the NumPy side: the per-scene arrays its
compiled kernels (:mod:`._cpu_project`) read, and the two ways of calling them, one compiled
pass for pinhole cameras and the camera model's NumPy methods plus a compiled rest for every
other model (with a panorama's seam copies and half-turn clip).  Used by
:class:`splatgl.renderers.cpu.CpuRenderer`; like it, needs numba only through ``kernels``.
"""

from __future__ import annotations

from types import SimpleNamespace
from typing import Iterable

import numpy as np

from ..cameras.equirect import eye_space, wrap_copies, wrap_shift
from ..cameras.view import View, anchored_camera
from ..constants import JACOBIAN_CLAMP, LOW_PASS, sh_coeff_count
from ..scene.quaternion import quat_to_rotmat
from ..scene.splats import Scene
from ..reference.stages import tile_grid
from ..splatmath.project import splat_reach, to_camera
from .options import CpuOptions


class Stage1:
    """One scene's projection inputs (float32: ``R S`` per splat, opacities, SH; the means
    relative to the last view's anchor) and the projections of a view.

    Each projection returns (mean2d, conic, opacity, reach, colour, depth, box, rect), one row
    per splat (a panorama: then one more per seam copy); a culled row has an empty ``rect``.
    """

    def __init__(self, scene: Scene, options: CpuOptions, kernels: SimpleNamespace):
        f32 = np.float32
        self.kernels, self.scene, self.count = kernels, scene, scene.count
        rot = quat_to_rotmat(scene.rotations.astype(f32))
        self._rs = np.ascontiguousarray(rot * scene.scales.astype(f32)[:, None, :], f32)
        self._opacity = np.ascontiguousarray(scene.opacities, f32)
        self._sh = np.ascontiguousarray(scene.sh, f32)
        degree = scene.sh_degree if options.sh_degree is None else min(options.sh_degree,
                                                                        scene.sh_degree)
        self._coeffs = sh_coeff_count(degree)
        self.antialias = bool(options.antialias)
        self._anchor: tuple[bytes, np.ndarray] | None = None   # (anchor bytes, means - anchor)
        self._reach: tuple[float, np.ndarray] | None = None     # (scale, world reach): panoramas
        self._every: np.ndarray | None = None     # arange(count): every row, for the pinhole pass

    def relative_means(self, anchor: np.ndarray) -> np.ndarray:
        """``means - anchor`` in float32 (the subtraction in float64), kept per anchor."""
        key = np.asarray(anchor, np.float64).tobytes()
        if self._anchor is None or self._anchor[0] != key:
            rel = np.asarray(self.scene.means, np.float64) - np.asarray(anchor, np.float64)
            self._anchor = key, np.ascontiguousarray(rel, np.float32)
        return self._anchor[1]

    def inputs(self, view: View, rows: np.ndarray | None):
        """``(means - anchor, R S, opacities, SH)`` of the scene rows ``rows`` (ascending, the
        view's cull's: :meth:`splatgl.renderers.cpu.CpuRenderer.kept_rows`), or of every row
        (None: no copy): the NumPy model pass's inputs.  A copy keeps its source's read-only
        flag (numba compiles each apart)."""
        arrays = (self.relative_means(view.anchor), self._rs, self._opacity, self._sh)
        if rows is None:
            return arrays
        out = []
        for a in arrays:
            part = a[rows]
            part.flags.writeable = a.flags.writeable
            out.append(part)
        return tuple(out)

    def pinhole(self, view: View, parts: Iterable[tuple[int, int]], rows: np.ndarray | None = None):
        """Stage 1 for a pinhole camera, compiled: (mean2d, conic, opacity, reach, colour,
        depth, box, rect) of every splat (of the scene rows ``rows`` only, int64 ascending, one
        output row each: the kernel reads them in place), computed over the ranges ``parts``
        of its output rows in turn (the caller may check for input between them)."""
        rel = self.relative_means(view.anchor)
        if rows is None:
            if self._every is None or self._every.size != self.count:
                self._every = np.arange(self.count, dtype=np.int64)
            rows = self._every
        n = rows.size
        cam = anchored_camera(view.camera, view.anchor)
        tx, ty = cam.tan_half_fov
        params = np.concatenate([
            np.asarray(cam.rotation, np.float64).ravel(), np.asarray(cam.translation, np.float64),
            [cam.fx, cam.fy, cam.cx, cam.cy,
             float(np.float32(JACOBIAN_CLAMP * tx)), float(np.float32(JACOBIAN_CLAMP * ty)),
             float(view.near_in(np.float32)),
             LOW_PASS if view.low_pass is None else view.low_pass]])
        grid = tile_grid(cam.width, cam.height)
        out = outputs(n)
        center = np.asarray(cam.center, np.float32)
        for a, b in parts:
            self.kernels.project_pinhole(
                rel, self._rs, self._opacity, self._sh, rows[a:b], self._coeffs, params,
                center, float(grid[0]), float(grid[1]), self.antialias, *(o[a:b] for o in out))
        return out

    def model(self, view: View, parts: Iterable[tuple[int, int]], rows: np.ndarray | None = None):
        """Stage 1 for every other camera model (fisheye, OpenCV distortion, orthographic,
        equirectangular): the model's own NumPy methods give each part's camera-space points,
        pixel positions, Jacobians, culling and depths, as in the reference's stage 1; the rest
        is :func:`~._cpu_project.project_model`, compiled.  A panorama then gets the
        reference's second rows for splats that may reach across its seam, and every box is
        cut to half a turn around its splat (:func:`clip_to_half_turn`).  ``parts`` as in
        :meth:`pinhole`, and so ``rows``."""
        f32 = np.float32
        rel, rs, opacity, sh = self.inputs(view, rows)
        n = rel.shape[0]
        cam = anchored_camera(view.camera, view.anchor)
        model, near = cam.model, view.near_in(f32)
        period = model.seam_period(cam)
        params = np.concatenate([np.asarray(cam.rotation, np.float64).ravel(),
                                 [LOW_PASS if view.low_pass is None else view.low_pass]])
        grid = tile_grid(cam.width, cam.height)
        center = np.asarray(cam.center, f32)
        uv, jac = np.empty((n, 2), f32), np.empty((n, 2, 3), f32)
        visible, p_cam = np.empty(n, np.bool_), np.empty((n, 3), f32)
        out = outputs(n)

        def finish(part, into: slice, u, ok):   # the compiled rest: input rows -> out[into]
            # the scene's opacities and SH are read-only, and so their slices; the seam copies'
            # rows (fancy indexing) are made so too: numba compiles each flag apart (9 s here)
            self.kernels.project_model(
                rel[part], rs[part], _read_only(opacity[part]),
                _read_only(sh[part]), self._coeffs, params, center, float(grid[0]),
                float(grid[1]), self.antialias, u, jac[part], ok,
                *(o[into] for i, o in enumerate(out) if i != 5))

        for a, b in parts:
            with np.errstate(all="ignore"):
                p_cam[a:b] = eye_space(to_camera(rel[a:b], cam), cam)
                uv[a:b] = model.project(p_cam[a:b], cam)
                jac[a:b] = model.jacobian(p_cam[a:b], cam)
                visible[a:b] = model.visible(p_cam[a:b], cam, near)
                out[5][a:b] = model.depth(p_cam[a:b])
            finish(slice(a, b), slice(a, b), uv[a:b], visible[a:b])
        if period is None:
            return out
        # the reference's wrapped copies, appended in row order after every splat
        if self._reach is None or self._reach[0] != cam.scale:
            self._reach = cam.scale, splat_reach(self.scene.scales.max(axis=1) * cam.scale,
                                                 self.scene.opacities)
        reach = self._reach[1] if rows is None else self._reach[1][rows]
        dup = np.flatnonzero(visible & wrap_copies(p_cam, reach, cam))
        out = tuple(np.concatenate([o, o[dup]]) for o in out)   # depth and shapes for the copies
        shifted = uv[dup]
        shifted[:, 0] += wrap_shift(shifted[:, 0], cam)
        finish(dup, slice(n, None), shifted, np.ones(len(dup), np.bool_))
        clip_to_half_turn(out[6], out[0], period)
        return out


def clip_to_half_turn(box: np.ndarray, mean2d: np.ndarray, period: float) -> None:
    """Cut each pixel box's columns to those whose centre lies within half a turn of the
    splat, ``|x + 0.5 - u| <= period / 2`` in float32, as the reference clips a panorama's
    splats (a splat near the camera or a pole can be wider than the whole image; its wrapped
    copy covers the other side).  In place."""
    f32 = np.float32
    half, u = f32(0.5 * period), mean2d[:, 0].astype(f32)
    span = 4.0 * float(half) + 4.0                      # keeps the integers small and exact

    def inside(j: np.ndarray) -> np.ndarray:
        return np.abs((j + 0.5).astype(f32) - u) <= half

    centre = np.clip(u.astype(np.float64) - 0.5, -span, span)
    lo = np.ceil(centre - float(half)).astype(np.int64)
    hi = np.floor(centre + float(half)).astype(np.int64)      # last column, inclusive
    lo = np.where(inside(lo - 1), lo - 1, np.where(inside(lo), lo, lo + 1))
    hi = np.where(inside(hi + 1), hi + 1, np.where(inside(hi), hi, hi - 1))
    box[:, 0] = np.maximum(box[:, 0], lo)
    box[:, 1] = np.minimum(box[:, 1], hi + 1)


def _read_only(a: np.ndarray) -> np.ndarray:
    """``a``, marked read-only (no copy)."""
    a.flags.writeable = False
    return a


def outputs(n: int) -> tuple[np.ndarray, ...]:
    """Zeroed stage-1 outputs for ``n`` rows: mean2d (2), conic (3), opacity, reach, colour
    (3), depth (float32), box (4) and tile rectangle (4) (int32)."""
    f32 = np.float32
    return (np.zeros((n, 2), f32), np.zeros((n, 3), f32), np.zeros(n, f32), np.zeros(n, f32),
            np.zeros((n, 3), f32), np.zeros(n, f32), np.zeros((n, 4), np.int32),
            np.zeros((n, 4), np.int32))
