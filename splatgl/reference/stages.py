"""Stage ``project`` of the reference: per-splat screen quantities, culling and tile rectangles.

The twin of 3DGS's ``preprocessCUDA`` (and gsplat's projection + tile bounds under
:attr:`Compat.GSPLAT`).  The math itself lives in :mod:`splatgl.splatmath.project`; this module adds the
reference's culling rules and its tile rectangles.

Coordinates: ``mean2d`` is in splatgl's image coordinates (pixel (i, j) has its centre at
``(j + 0.5, i + 0.5)``).  3DGS works in pixel-index coordinates instead (centre of pixel j at
``j``), so its ``getRect`` sees ``p = mean2d - 0.5``; the INRIA rectangle below uses exactly
that ``p``, which makes the set of tiles identical to what 3DGS bins for the same camera.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

import dataclasses

from ..cameras.equirect import wrap_copies, wrap_shift
from ..cameras.view import View
from ..splatmath import project as pm
from ..splatmath import surfel as sf
from ..cameras.camera import Camera
from ..cameras.fisheye import Fisheye
from ..constants import ALPHA_MIN, TILE_SIZE
from ..scene.splats import Scene, SplatKind
from ..scene.settings import RenderSettings
from ..constants import GSPLAT_EXTENT_SIGMAS
from ..scene.settings import Order
from . import emulation as em_rules
from ..splatmath import peak as pp
from .options import Compat, ReferenceOptions


@dataclass(frozen=True)
class ProjectedSplats:
    """Output of :func:`project`: one row per input splat (culled rows included, flagged).

    Attributes (N rows; ``float`` means the render dtype, float32 or float64):
        visible: (N,) bool; False for splats culled (near plane, ``det <= 0``, empty rect, ...).
        depth: (N,) float sort key (world units): view-space z; for fisheye and
            equirectangular cameras the distance ``|p|`` (:meth:`~splatgl.cameras.model.CameraModel.depth`),
            except a fisheye under GSPLAT, which keeps gsplat's view z (:func:`gsplat_fisheye`).
        mean2d: (N, 2) float image coordinates (u, v) in pixels, centre convention ``j + 0.5``.
        conic: (N, 3) float inverse 2D covariance (a, b, c), ``Q = [[a, b], [b, c]]``, 1/px^2.
        opacity: (N,) float opacity in [0, 1] (times the AA factor when antialiasing).
        color: (N, 3) float SH colour (>= 0, unbounded above).
        radius: (N, 2) int64 extent (x, y) in pixels; 0 for culled rows.  INRIA: both equal
            ``ceil(3 sqrt(lambda_max))``.
        rect_min, rect_max: (N, 2) int64 tile rectangle, ``[min, max)`` in tile units (x, y),
            clamped to the grid; empty (min == max) for culled rows.
        width, height: image size in pixels.  grid: (tiles_x, tiles_y).
        surfel_rows, depth_rows: 2DGS surfels only (None for 3DGS): (N, 3, 3) centred
            ``T' = A P H`` and (N, 3) view-z rows (:class:`splatgl.splatmath.surfel.SurfelScreen`); then
            ``mean2d`` is the projected centre (the low-pass centre), ``conic`` is zero and
            ``radius`` holds the per-axis ``ceil`` of the box half extents.
        wrap_period: equirectangular cameras only: pixels per turn of longitude; every splat
            reaches at most half of it either side of its centre, and rows past the scene's
            count are the second copies of splats on the +-180 degree seam
            (:func:`splatgl.cameras.equirect.wrap_copies`).
        source: (rows,) int64 scene row of each row (the seam copies name their originals),
            or None where the rows are the scene's own.
        key_bits: (N,) uint64 low 32 bits of the sort keys when an emulation knob changes them
            (:func:`splatgl.reference.emulation.key_bits`); None: the float32 bits of ``depth``.
        clip_q, clip_rows: an ``extent`` knob's per-pixel clip
            (:class:`splatgl.reference.emulation.Support`), or None.
        peak: (N, 9) float coefficients of the depth at which each splat peaks along a pixel's
            ray, for the per-pixel order (:func:`splatgl.splatmath.peak.peak_coefficients`),
            or None; rays: the camera's pixel rays with it (:class:`splatgl.splatmath.peak.Rays`).
    """

    visible: np.ndarray
    depth: np.ndarray
    mean2d: np.ndarray
    conic: np.ndarray
    opacity: np.ndarray
    color: np.ndarray
    radius: np.ndarray
    rect_min: np.ndarray
    rect_max: np.ndarray
    width: int
    height: int
    grid: tuple[int, int]
    surfel_rows: np.ndarray | None = None
    depth_rows: np.ndarray | None = None
    wrap_period: float | None = None
    source: np.ndarray | None = None
    key_bits: np.ndarray | None = None
    clip_q: np.ndarray | None = None
    clip_rows: np.ndarray | None = None
    peak: np.ndarray | None = None
    rays: "pp.Rays | None" = None

    @property
    def is_surfel(self) -> bool:
        return self.surfel_rows is not None

    @property
    def count(self) -> int:
        return int(self.visible.shape[0])

    @property
    def dtype(self) -> np.dtype:
        return self.mean2d.dtype

    @property
    def n_tiles(self) -> int:
        return self.grid[0] * self.grid[1]

    @property
    def tiles_touched(self) -> np.ndarray:
        """(N,) int64 number of tiles in each splat's rectangle (0 for culled rows)."""
        size = np.maximum(self.rect_max - self.rect_min, 0)
        return np.where(self.visible, size[:, 0] * size[:, 1], 0)


def tile_grid(width: int, height: int) -> tuple[int, int]:
    """(tiles_x, tiles_y) covering a ``width`` x ``height`` image with 16 x 16 tiles."""
    return (width + TILE_SIZE - 1) // TILE_SIZE, (height + TILE_SIZE - 1) // TILE_SIZE


def inria_rect(mean2d: np.ndarray, radius: np.ndarray, grid: tuple[int, int]
               ) -> tuple[np.ndarray, np.ndarray]:
    """3DGS ``getRect``: tile rectangles of squares of ``radius`` pixels around ``mean2d``.

    ``rect_min = clamp((int)((p - r) / 16), 0, grid)``, ``rect_max = clamp((int)((p + r + 15) /
    16), 0, grid)`` with ``p = mean2d - 0.5`` (3DGS pixel-index coordinates), C truncation, the
    arithmetic in ``mean2d``'s dtype.  (N, 2) float, (N,) int -> two (N, 2) int64 arrays.
    """
    dt = mean2d.dtype.type
    p = mean2d - dt(0.5)
    r = radius.astype(mean2d.dtype)[:, None]
    hi = np.array(grid, np.int64)
    with np.errstate(invalid="ignore", over="ignore"):
        lo_f = np.trunc((p - r) / dt(TILE_SIZE))
        hi_f = np.trunc((p + r + dt(TILE_SIZE - 1)) / dt(TILE_SIZE))
    return _clamp_int(lo_f, hi), _clamp_int(hi_f, hi)


def gsplat_rect(mean2d: np.ndarray, radius_xy: np.ndarray, grid: tuple[int, int]
                ) -> tuple[np.ndarray, np.ndarray]:
    """gsplat tile bounds: ``[floor(u/16 - r_x/16), ceil(u/16 + r_x/16))`` per axis, clamped.

    (N, 2) float means (centre convention ``j + 0.5``), (N, 2) int radii -> (N, 2) int64 each.
    """
    dt = mean2d.dtype.type
    t = mean2d / dt(TILE_SIZE)
    tr = radius_xy.astype(mean2d.dtype) / dt(TILE_SIZE)
    hi = np.array(grid, np.int64)
    with np.errstate(invalid="ignore", over="ignore"):
        return _clamp_int(np.floor(t - tr), hi), _clamp_int(np.ceil(t + tr), hi)


def box_rect(center: np.ndarray, half: np.ndarray, grid: tuple[int, int]
             ) -> tuple[np.ndarray, np.ndarray]:
    """Tile rectangles of pixel boxes ``center +- half`` (2DGS surfels), conservative.

    The 3DGS ``getRect`` form in pixel-index coordinates (``p = center - 0.5``), but exact about
    which pixels the box holds: indices ``ceil(p - half)`` .. ``floor(p + half)``, tiles
    ``[floor(first / 16), floor(last / 16) + 1)`` clamped to the grid.  (getRect's
    ``(int)((p + r + 15) / 16)`` drops the tile of pixel ``floor(p + r)`` when that pixel starts
    a tile and ``p + r`` is not an integer; harmless at 3 sigma, visible with a tight box.)
    (N, 2) float centres and half extents (pixels) -> two (N, 2) int64 arrays; a box holding no
    pixel centre gets an empty rectangle.
    """
    dt = center.dtype.type
    p = center - dt(0.5)
    hi = np.array(grid, np.int64)
    with np.errstate(invalid="ignore", over="ignore"):
        first = np.ceil(p - half)
        last = np.floor(p + half)
        lo_t = _clamp_int(np.floor(first / dt(TILE_SIZE)), hi)
        hi_t = _clamp_int(np.floor(last / dt(TILE_SIZE)) + dt(1.0), hi)
        hi_t = np.where(last >= first, hi_t, lo_t)
    return lo_t, hi_t


def _clamp_int(values: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """Float tile coordinates -> int64 clamped to [0, hi] (NaN -> 0)."""
    v = np.nan_to_num(values, nan=0.0, posinf=1e18, neginf=-1e18)
    return np.clip(v, 0, hi).astype(np.int64)


def gsplat_radius(cov2d: np.ndarray, opacity: np.ndarray) -> np.ndarray:
    """gsplat's per-axis extent ``ceil(min(3.33, sqrt(2 ln(o / (1/255)))) sqrt(cov_ii))``.

    (N, 2, 2) dilated covariances (px^2), (N,) opacities -> (N, 2) int64 radii (x, y) in
    pixels; 0 where ``o < 1/255``.
    """
    dt = cov2d.dtype.type
    with np.errstate(divide="ignore", invalid="ignore"):
        k = np.sqrt(np.maximum(dt(2.0) * np.log(opacity / dt(ALPHA_MIN)), dt(0.0)))
    k = np.minimum(dt(GSPLAT_EXTENT_SIGMAS), k)
    k = np.where(opacity >= dt(ALPHA_MIN), k, dt(0.0))
    diag = np.stack([cov2d[:, 0, 0], cov2d[:, 1, 1]], -1)
    with np.errstate(invalid="ignore"):
        r = np.ceil(k[:, None] * np.sqrt(np.maximum(diag, dt(0.0))))
    return np.nan_to_num(r, nan=0.0, posinf=0.0).astype(np.int64)


def project(scene: Scene, view: View, settings: RenderSettings | None = None,
            dtype: np.dtype | type = np.float32,
            options: ReferenceOptions | None = None) -> ProjectedSplats:
    """Reference stage 1: project every splat and decide which tiles it touches.

    Culling (a culled row gets ``visible = False``, radius 0 and an empty rectangle): the
    model's :meth:`~splatgl.cameras.model.CameraModel.visible` (view z at or below the view's
    near plane; fisheye and panorama: the distance and a fisheye's angle limit, but view z for
    a fisheye under GSPLAT, :func:`gsplat_fisheye`; lens distortion: also its fold radius), non-finite values,
    ``det(cov2d) <= 0``, an empty tile rectangle; under GSPLAT also ``o < 1/255``, zero radii
    and an extent entirely off screen.

    2DGS surfels go to :func:`project_surfels` (same culling idea, the surfel's own box).

    Args:
        scene: a 3DGS or 2DGS scene.
        view: the frame's :class:`~splatgl.cameras.view.View` (its camera, near plane, anchor).
        settings: antialiasing, SH degree cap (default RenderSettings()).
        dtype: float32 (mimics the GPU) or float64 (checks).
        options: convention (default INRIA).
    """
    settings = RenderSettings() if settings is None else settings
    options = ReferenceOptions() if options is None else options
    dt = np.dtype(dtype)
    if dt not in (np.dtype(np.float32), np.dtype(np.float64)):
        raise ValueError(f"reference dtype must be float32 or float64, got {dt}")
    camera = view.camera
    camera.model.check_surfels(scene.kind is SplatKind.SURFEL_2D)
    if scene.kind is SplatKind.SURFEL_2D:
        return project_surfels(scene, view, settings, dt, options)
    near = view.near_in(dt)
    grid = tile_grid(camera.width, camera.height)
    em = options.emulation
    settings = em_rules.projection_settings(settings, em)
    world_means, scales = em_rules.scene_arrays(scene.means, scene.scales, em)
    means, view = pm.anchored(world_means, view.anchor, camera, dt)  # relative: float32-safe
    with np.errstate(all="ignore"):
        pr = pm.project(means, scene.rotations.astype(dt),
                        scales.astype(dt), scene.opacities.astype(dt), scene.sh.astype(dt),
                        view, settings.antialias, settings.sh_degree, em.low_pass)
    finite = (np.isfinite(pr.mean2d).all(1) & np.isfinite(pr.conic).all(1)
              & np.isfinite(pr.cov2d).all((1, 2)) & np.isfinite(pr.color).all(1)
              & np.isfinite(pr.opacity))
    as_gsplat = gsplat_fisheye(view, options)
    if as_gsplat:  # gsplat's sort key and near test: view z, as for a pinhole camera
        pr = dataclasses.replace(pr, depth=pr.p_cam[:, 2])
    # the model's own rule (view z beyond near for a pinhole; a lens's distance and angle; a
    # distorted camera's fold radius), or gsplat's view z
    visible = pr.depth > near if as_gsplat else view.model.visible(pr.p_cam, view, near)
    ok = visible & finite & (pr.det > 0)
    pr, ok, source = _wrap_copies(pr, ok, scene, view)
    mean2d = np.where(ok[:, None], pr.mean2d, dt.type(0.0)).astype(dt)
    cov2d = np.where(ok[:, None, None], pr.cov2d, dt.type(1.0)).astype(dt)

    clip = None
    if em.extent != "tiles":
        clip = em_rules.support(em.extent, cov2d, pr.opacity.astype(dt), options.alpha_min)
        radius = np.where(ok[:, None], np.ceil(clip.half), 0)
        rect_min, rect_max = box_rect(mean2d, clip.half.astype(dt), grid)
    elif options.compat is Compat.INRIA:
        r = np.where(ok, pm.reference_radius(cov2d), 0)
        radius = np.stack([r, r], -1)
        rect_min, rect_max = inria_rect(mean2d, r, grid)
    else:
        radius = np.where(ok[:, None], gsplat_radius(cov2d, pr.opacity.astype(dt)), 0)
        ok &= (radius > 0).any(1)
        ok &= gsplat_on_screen(mean2d, radius, camera, dt)
        rect_min, rect_max = gsplat_rect(mean2d, radius, grid)
    ok, rect_min, rect_max, radius, clean = _mask_culled(ok, rect_min, rect_max, radius, dt)

    bits = em_rules.key_bits(em, pr.depth, pr.p_cam, ok)
    return ProjectedSplats(
        visible=ok, depth=clean(pr.depth), mean2d=clean(mean2d), conic=clean(pr.conic),
        opacity=clean(pr.opacity), color=clean(pr.color), radius=radius.astype(np.int64),
        rect_min=rect_min, rect_max=rect_max, width=camera.width, height=camera.height,
        grid=grid, wrap_period=camera.model.seam_period(camera), source=source,
        key_bits=None if bits is None else np.where(ok, bits, np.uint64(0)),
        clip_q=None if clip is None or clip.clip_q is None else clean(clip.clip_q),
        clip_rows=None if clip is None or clip.clip_rows is None else clean(clip.clip_rows),
        peak=(pp.peak_coefficients(pr.p_cam, scene.rotations, scales, view, ok, dt)
              if options.order is Order.PER_PIXEL else None),
        rays=pp.Rays.of(camera) if options.order is Order.PER_PIXEL else None)


def gsplat_fisheye(camera: Camera, options: ReferenceOptions) -> bool:
    """True where the reference follows gsplat's EWA fisheye rather than splatgl's lens rules.

    gsplat treats a fisheye as it does a pinhole camera: it culls centres with view z below the
    near plane and sorts by view z.  splatgl's own rule for a fisheye (any convention but
    GSPLAT) is the distance ``|p|`` for both (:meth:`~splatgl.cameras.model.CameraModel.depth`): it stays
    positive and ordered behind the camera plane, where a fisheye of 180 degrees or more
    still sees, and does not change as the camera turns about its centre.  The two orders
    differ wherever overlapping splats swap between them (docs/camera-models.md measures it).
    """
    return options.compat is Compat.GSPLAT and isinstance(camera.model, Fisheye)


def _wrap_copies(pr: pm.Projected, ok: np.ndarray, scene: Scene, view: Camera
                 ) -> tuple[pm.Projected, np.ndarray, np.ndarray | None]:
    """Equirectangular cameras: append a second row, one turn of longitude away, for every
    kept splat that may reach across the +-180 degree seam (:func:`splatgl.cameras.equirect.wrap_copies`,
    the quad path's rule), and the scene row of every row; other cameras unchanged (None)."""
    if view.model.seam_period(view) is None:
        return pr, ok, None
    reach = pm.splat_reach(scene.scales.max(axis=1) * view.scale, scene.opacities)
    dup = np.flatnonzero(ok & wrap_copies(pr.p_cam, reach, view))
    rows = np.concatenate([np.arange(ok.shape[0]), dup])
    taken = {f.name: getattr(pr, f.name)[rows] for f in dataclasses.fields(pr)}
    mean2d = taken["mean2d"].copy()
    mean2d[ok.shape[0]:, 0] += wrap_shift(mean2d[ok.shape[0]:, 0], view)
    taken["mean2d"] = mean2d
    return pm.Projected(**taken), ok[rows], rows


def gsplat_on_screen(mean2d: np.ndarray, radius: np.ndarray, camera: Camera, dt) -> np.ndarray:
    """(N,) gsplat's screen test: the box ``mean2d +- radius`` (per axis) overlaps the image."""
    u, v = mean2d[:, 0], mean2d[:, 1]
    rx, ry = radius[:, 0].astype(dt), radius[:, 1].astype(dt)
    return ~((u + rx <= 0) | (u - rx >= camera.width) | (v + ry <= 0)
             | (v - ry >= camera.height))


def _mask_culled(ok, rect_min, rect_max, radius, dt):
    """Cull empty rectangles too, zero every culled row; returns the arrays and ``clean(a)``,
    which zeroes culled rows of any per-splat array and casts it to ``dt``."""
    ok = ok & ((rect_max - rect_min) > 0).all(1)
    rect_min = np.where(ok[:, None], rect_min, 0)
    rect_max = np.where(ok[:, None], rect_max, 0)
    radius = np.where(ok[:, None], radius, 0)

    def clean(a: np.ndarray) -> np.ndarray:
        mask = ok.reshape((-1,) + (1,) * (a.ndim - 1))
        return np.ascontiguousarray(np.where(mask, a, 0).astype(dt))

    return ok, rect_min, rect_max, radius, clean


def project_surfels(scene: Scene, view: View, settings: RenderSettings,
                    dtype: np.dtype, options: ReferenceOptions | None = None) -> ProjectedSplats:
    """Stage 1 for 2DGS surfels: centred ``T``, low-pass centre, SH colour and tile rects.

    INRIA (the official rasterizer's setup): the low-pass centre is the projected centre, the
    rectangle is :func:`box_rect` of the box of :func:`splatgl.splatmath.surfel.surfel_bounds` (the quad
    path draws that same box) and ``radius`` the per-axis ``ceil`` of its half extents.
    Culled: centre view z at or below the near plane, ``o <= 1/255``, non-finite values, an
    empty box or rectangle.

    GSPLAT (gsplat's ``fully_fused_projection_2dgs``): the low-pass centre is ``means2d``, the
    centre of the image of the 1-sigma ellipse (:func:`splatgl.splatmath.surfel.gsplat_screen`; the rows
    are centred on it), ``radius = ceil(3.33 extent)`` per axis and the rectangle
    :func:`gsplat_rect`.  Culled: centre view z at or below the near plane, ``C*_22 = 0``,
    non-finite values, the box ``means2d +- radius`` off screen; no opacity cull.
    Antialiasing does not apply to surfels.  ``depth`` is the centre's view z (the sort key).
    """
    options = ReferenceOptions() if options is None else options
    dt = np.dtype(dtype)
    camera = view.camera
    near = view.near_in(dt)
    grid = tile_grid(camera.width, camera.height)
    em = options.emulation          # extent, low_pass, compensation do not apply to surfels
    settings = em_rules.projection_settings(settings, em)
    world_means, scales = em_rules.scene_arrays(scene.means, scene.scales, em)
    means, view = pm.anchored(world_means, view.anchor, camera, dt)  # relative: float32-safe
    opac = scene.opacities.astype(dt)
    with np.errstate(all="ignore"):
        scr = sf.surfel_screen(means, scene.rotations.astype(dt), scales.astype(dt), view)
        color = pm.sh_color(scene.sh.astype(dt), pm.view_dirs(means, view), settings.sh_degree)
    ok = ((scr.view_z > dt.type(near)) & np.isfinite(color).all(1)
          & np.isfinite(scr.depth_row).all(1))
    if options.compat is Compat.GSPLAT:
        gs = sf.gsplat_screen(scr)
        with np.errstate(all="ignore"):
            radius_f = np.ceil(dt.type(GSPLAT_EXTENT_SIGMAS) * gs.extent)
        ok &= gs.ok & np.isfinite(gs.rows).all((1, 2))
        radius = np.where(ok[:, None], radius_f, 0).astype(np.int64)
        ok &= gsplat_on_screen(gs.means2d, radius, camera, dt)
        center = np.where(ok[:, None], gs.means2d, dt.type(0.0))
        rect_min, rect_max = gsplat_rect(center, radius, grid)
        rows = gs.rows
    else:
        with np.errstate(all="ignore"):
            box = sf.surfel_bounds(scr, opac, view, near)
        ok &= box.visible
        radius = np.where(ok[:, None], np.ceil(box.half), 0).astype(np.int64)
        rect_min, rect_max = box_rect(box.center, box.half, grid)
        center, rows = scr.center, scr.rows
    ok, rect_min, rect_max, radius, clean = _mask_culled(ok, rect_min, rect_max, radius, dt)

    bits = em_rules.key_bits(em, scr.view_z, pm.to_camera(means, view), ok)
    return ProjectedSplats(
        key_bits=None if bits is None else np.where(ok, bits, np.uint64(0)),
        visible=ok, depth=clean(scr.view_z), mean2d=clean(center),
        conic=np.zeros((scene.count, 3), dt), opacity=clean(opac), color=clean(color),
        radius=radius, rect_min=rect_min, rect_max=rect_max, width=camera.width,
        height=camera.height, grid=grid, surfel_rows=clean(rows),
        depth_rows=clean(scr.depth_row))
