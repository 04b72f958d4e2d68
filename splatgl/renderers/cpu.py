"""The CPU renderer (``--renderer cpu``): the reference's per-tile algorithm, compiled with numba.

On a machine without a GPU, OpenGL is llvmpipe, and the quad path pays llvmpipe's cost for
every quad and fragment (about 1 us a quad in its single-threaded front end, and blending in
a float target).  This renderer skips OpenGL: the reference's five stages (project, key
emission, sort, tile ranges, per-tile blending) run as three compiled passes
(:mod:`splatgl.renderers._cpu_project`, :mod:`splatgl.renderers._cpu_raster`), the tiles shared by every core, and each splat
evaluated only on the pixels of its box where it can reach alpha 1/255.  Its image is the
reference's own algorithm in float32, so it agrees with :func:`splatgl.reference.render_reference`
more closely than the quad path does (tests/test_cpu_renderer.py states the tolerances).
docs/interactive.md measures it against the quad path and limacv's viewer.

It needs numba (the ``fast`` extra) and draws 3DGS splats with colour, alpha and the depth
layer, under the inria rules, with the global order.  Pinhole cameras project in a compiled
pass too; every other camera model the reference draws (fisheye, equirectangular, OpenCV
distortion, orthographic) projects with the reference's NumPy stage 1, which is slower.
"""

from __future__ import annotations

import importlib
import importlib.util
import time
from dataclasses import dataclass
from types import SimpleNamespace

import numpy as np

from ..cameras.equirect import eye_space, wrap_copies, wrap_shift
from ..cameras.pinhole import Pinhole
from ..cameras.view import View, anchored_camera
from ..constants import JACOBIAN_CLAMP, LOW_PASS, sh_coeff_count
from ..errors import SplatglError
from ..model.quaternion import quat_to_rotmat
from ..model.scene import Scene, SplatKind
from ..model.settings import RendererKind, RenderSettings, check_convention, check_fidelity
from ..output.layers import BASE, Layer, RenderOutput
from ..output.under import UnderLayer
from ..order.sort import depth_sort
from ..reference.stages import tile_grid
from ..twins.project import splat_reach, to_camera
from .quad_layers import composite

#: The layers this renderer draws.
LAYERS = frozenset(BASE | {Layer.DEPTH})


@dataclass(frozen=True)
class CpuTimes:
    """Seconds of the last frame's stages, and its tile-list length."""

    project: float
    sort: float
    bin: float
    rasterize: float
    n_keys: int
    drawn: int = 0          # splats drawn (a tile rectangle on screen)

    @property
    def total(self) -> float:
        return self.project + self.sort + self.bin + self.rasterize


def installed() -> bool:
    """numba (the ``fast`` extra) is importable."""
    return importlib.util.find_spec("numba") is not None


def check_available() -> None:
    """A one-line error naming the extra when numba is missing."""
    if not installed():
        raise SplatglError("--renderer cpu needs numba: pip install 'splatgl[fast]'")


def _kernels() -> SimpleNamespace:
    """The compiled stages (:mod:`._cpu_project`, :mod:`._cpu_raster`)."""
    check_available()
    project_mod = importlib.import_module("splatgl.renderers._cpu_project")
    raster_mod = importlib.import_module("splatgl.renderers._cpu_raster")
    return SimpleNamespace(project_pinhole=project_mod.project_pinhole,
                           pack=raster_mod.pack,
                           bin_tiles=raster_mod.bin_tiles, rasterize=raster_mod.rasterize,
                           project_model=project_mod.project_model,
                           REC_SIZE=raster_mod.REC_SIZE)


def check_scene(scene: Scene, settings: RenderSettings) -> None:
    """Refuse what the CPU renderer does not draw, with one line naming it."""
    if scene.kind is SplatKind.SURFEL_2D:
        raise SplatglError("--renderer cpu draws 3DGS splats; this scene holds 2DGS surfels "
                           "(use --renderer quad or tile)")
    check_convention(settings.convention, RendererKind.CPU)
    check_fidelity(settings, RendererKind.CPU)


def tile_order(n_tiles: int, threads: int) -> np.ndarray:
    """Tile ids in the order the compiled loop hands them out: its threads take contiguous
    runs, so the ids are interleaved (thread c gets c, c + n, c + 2n, ...), which spreads busy
    and empty parts of the image over all of them.  Measured against the plain order (blend
    stage, 8 views of the flight's orbit twice, 2 cores): the plain order took 0.98x as long
    on donut, 1.09x on biker and 1.27x on guitar, a small object in the middle of the view."""
    threads = max(1, threads)
    return np.concatenate([np.arange(c, n_tiles, threads, dtype=np.int64) for c in range(threads)])


class CpuRenderer:
    """Renders one scene on the CPU; reuse it across views.

    Attributes: ``scene``, ``settings``, ``last_times`` (:class:`CpuTimes` of the last
    frame, or None).  :meth:`render` has the GPU renderers' signature; :meth:`release` frees
    nothing (no GL objects) and is there for :class:`splatgl.api.Renderer`'s cache.
    """

    def __init__(self, scene: Scene, settings: RenderSettings):
        check_scene(scene, settings)
        self.k = _kernels()
        self.scene, self.settings = scene, settings
        self.last_times: CpuTimes | None = None
        self._anchor: tuple[bytes, np.ndarray] | None = None   # (anchor bytes, means - anchor)
        self._reach: tuple[float, np.ndarray] | None = None     # (scale, world reach): panoramas
        f32 = np.float32
        rot = quat_to_rotmat(scene.rotations.astype(f32))
        self._rs = np.ascontiguousarray(rot * scene.scales.astype(f32)[:, None, :], f32)
        self._opacity = np.ascontiguousarray(scene.opacities, f32)
        self._sh = np.ascontiguousarray(scene.sh, f32)
        degree = scene.sh_degree if settings.sh_degree is None else min(settings.sh_degree,
                                                                        scene.sh_degree)
        self._coeffs = sh_coeff_count(degree)
        self._tiles: dict[tuple, list[np.ndarray]] = {}     # the bands of each grid
        self._rec = np.empty((0, self.k.REC_SIZE), np.float32)   # the splat records, reused

    def _relative_means(self, anchor: np.ndarray) -> np.ndarray:
        """``means - anchor`` in float32 (the subtraction in float64), kept per anchor."""
        key = np.asarray(anchor, np.float64).tobytes()
        if self._anchor is None or self._anchor[0] != key:
            rel = np.asarray(self.scene.means, np.float64) - np.asarray(anchor, np.float64)
            self._anchor = key, np.ascontiguousarray(rel, np.float32)
        return self._anchor[1]

    def _project_pinhole(self, view: View, checkpoint=None):
        """Stage 1 compiled: (mean2d, conic, opacity, reach, colour, depth, box, rect); with
        ``checkpoint``, in parts of :data:`PART_SPLATS` splats, ``checkpoint()`` before each."""
        n = self.scene.count
        cam = anchored_camera(view.camera, view.anchor)
        tx, ty = cam.tan_half_fov
        params = np.concatenate([
            np.asarray(cam.rotation, np.float64).ravel(), np.asarray(cam.translation, np.float64),
            [cam.fx, cam.fy, cam.cx, cam.cy,
             float(np.float32(JACOBIAN_CLAMP * tx)), float(np.float32(JACOBIAN_CLAMP * ty)),
             float(view.near_in(np.float32)),
             LOW_PASS if view.low_pass is None else view.low_pass]])
        grid = tile_grid(cam.width, cam.height)
        out = _stage1_outputs(n)
        rel, center = self._relative_means(view.anchor), np.asarray(cam.center, np.float32)
        for a, b in _parts(n, checkpoint):
            self.k.project_pinhole(rel[a:b], self._rs[a:b], self._opacity[a:b], self._sh[a:b],
                                   self._coeffs, params, center, float(grid[0]), float(grid[1]),
                                   bool(self.settings.antialias), *(o[a:b] for o in out))
        return out

    def _project_model(self, view: View, checkpoint=None):
        """Stage 1 for every other camera model (fisheye, OpenCV distortion, orthographic,
        equirectangular): the model's own NumPy methods give each part's camera-space points,
        pixel positions, Jacobians, culling and depths, as in the reference's stage 1; the rest
        is :func:`~._cpu_project.project_model`, compiled.  A panorama then gets the
        reference's second rows for splats that may reach across its seam, and every box is
        cut to half a turn around its splat (:func:`_clip_to_half_turn`).  Parts and
        ``checkpoint`` as in :meth:`_project_pinhole`."""
        n, f32 = self.scene.count, np.float32
        cam = anchored_camera(view.camera, view.anchor)
        model, near = cam.model, view.near_in(f32)
        period = model.seam_period(cam)
        params = np.concatenate([np.asarray(cam.rotation, np.float64).ravel(),
                                 [LOW_PASS if view.low_pass is None else view.low_pass]])
        grid = tile_grid(cam.width, cam.height)
        rel, center = self._relative_means(view.anchor), np.asarray(cam.center, f32)
        uv, jac = np.empty((n, 2), f32), np.empty((n, 2, 3), f32)
        visible, p_cam = np.empty(n, np.bool_), np.empty((n, 3), f32)
        out = _stage1_outputs(n)

        def finish(rows, into: slice, u, ok):   # the compiled rest: scene rows -> out[into]
            self.k.project_model(rel[rows], self._rs[rows], self._opacity[rows], self._sh[rows],
                                 self._coeffs, params, center, float(grid[0]), float(grid[1]),
                                 bool(self.settings.antialias), u, jac[rows], ok,
                                 *(o[into] for i, o in enumerate(out) if i != 5))

        for a, b in _parts(n, checkpoint):
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
        dup = np.flatnonzero(visible & wrap_copies(p_cam, self._reach[1], cam))
        out = tuple(np.concatenate([o, o[dup]]) for o in out)   # depth and shapes for the copies
        shifted = uv[dup]
        shifted[:, 0] += wrap_shift(shifted[:, 0], cam)
        finish(dup, slice(n, None), shifted, np.ones(len(dup), np.bool_))
        _clip_to_half_turn(out[6], out[0], period)
        return out

    def render(self, view: View, layers: frozenset[Layer] = BASE,
               under: UnderLayer | None = None) -> RenderOutput:
        """The ``layers`` of one view (colour and alpha; depth when asked): RGB = C + (1 - A)
        background, alpha = A, as the quad path composites it; row 0 is the top."""
        layers = frozenset(layers)
        if under is not None:
            raise SplatglError("--renderer cpu cannot composite into --under geometry yet "
                               "(use --renderer quad)")
        if layers - LAYERS:
            names = ", ".join(sorted(layer.value for layer in layers - LAYERS))
            raise SplatglError(f"--renderer cpu draws colour, alpha and depth only, not {names} "
                               "(use --renderer quad)")
        rgba, depth = self.draw(view, Layer.DEPTH in layers)
        if any(self.settings.background):
            rgba = composite(rgba, self.settings.background)
        return RenderOutput(rgba, depth, layers | BASE)

    def draw(self, view: View, with_depth: bool = False, on_batch=None,
             bands: int = 1) -> tuple[np.ndarray, np.ndarray | None]:
        """``(premultiplied (H, W, 4) float32 (C, A), depth (H, W) or None)`` of one view, no
        background.  With ``on_batch``, the work is cut into pieces of a few tens of
        milliseconds (here, at 1M splats): projection and packing in parts of
        :data:`PART_SPLATS` splats, the sort and the binning whole, and the blend in ``bands``
        bands of tile rows; ``on_batch(done, total)`` (tiles blended) is called before each
        piece and may raise to abandon the frame (:mod:`splatgl.interactive.session` does, on
        input).  The image is the same however the work is cut."""
        w, h = view.width, view.height
        rgba = np.empty((h, w, 4), np.float32)
        depth = np.empty((h, w) if with_depth else (1, 1), np.float32)
        grid = tile_grid(w, h)
        n_tiles = grid[0] * grid[1]
        t0 = time.perf_counter()
        if self.scene.count == 0:
            rgba[...] = 0.0
            depth[...] = 0.0
            self.last_times = CpuTimes(0.0, 0.0, 0.0, time.perf_counter() - t0, 0, 0)
            return rgba, depth if with_depth else None
        done = 0

        def checkpoint() -> None:
            if on_batch is not None:
                on_batch(done, n_tiles)

        model = view.camera.model
        if type(model) is Pinhole:
            stage1 = self._project_pinhole(view, checkpoint)
        else:
            stage1 = self._project_model(view, checkpoint)
        mean2d, conic, opacity, reach, color, z, box, rect = stage1
        t1 = time.perf_counter()
        checkpoint()
        order = depth_order(z, rect)
        t2 = time.perf_counter()
        checkpoint()
        starts, rows = self.k.bin_tiles(order, rect, grid[0], n_tiles, 4 * _threads())
        rec = self._records(order.shape[0])
        for a, b in _parts(order.shape[0], checkpoint):
            self.k.pack(order[a:b], mean2d, conic, opacity, reach, color, z, box, rec[a:b])
        t3 = time.perf_counter()
        for tiles in self._bands(grid, bands):
            checkpoint()
            self.k.rasterize(starts, rows, tiles, rec, grid[0], rgba, depth, with_depth)
            done += tiles.shape[0]
        t4 = time.perf_counter()
        self.last_times = CpuTimes(t1 - t0, t2 - t1, t3 - t2, t4 - t3, int(rows.shape[0]),
                                   int(order.shape[0]))
        return rgba, depth if with_depth else None

    def _records(self, m: int) -> np.ndarray:
        """(m, REC_SIZE) float32 for :func:`~._cpu_raster.pack`, from a buffer kept between
        frames (grown by a quarter when short): a fresh one cost its page faults every frame,
        about 100 ms of the 1M-splat frame's 140 ms of packing here."""
        if self._rec.shape[0] < m:
            self._rec = np.empty((m + m // 4, self.k.REC_SIZE), np.float32)
        return self._rec[:m]

    def _bands(self, grid: tuple[int, int], bands: int) -> list[np.ndarray]:
        """The tile ids of each band of whole tile rows, each interleaved for the threads
        (:func:`tile_order`); one band: the whole grid."""
        key = (grid, max(1, min(bands, grid[1])))
        cached = self._tiles.get(key)
        if cached is None:
            threads, n = _threads(), key[1]
            cached = []
            for b in range(n):
                first, last = grid[1] * b // n * grid[0], grid[1] * (b + 1) // n * grid[0]
                cached.append(first + tile_order(last - first, threads))
            self._tiles[key] = cached
        return cached

    def release(self) -> None:
        """Nothing to free (numpy arrays only)."""


def depth_order(depth: np.ndarray, rect: np.ndarray) -> np.ndarray:
    """(M,) int64 rows with a tile rectangle, nearest first; equal depths in row order (the
    reference's stable key sort).  The quad path's sort (:func:`splatgl.order.sort.depth_sort`:
    one sort of unique 64-bit keys, the depth's float32 bits above the row), 5-9x faster here
    than NumPy's stable argsort of the floats.  Drawn rows lie beyond the (positive) near
    plane, so their depths are positive, as that sort needs."""
    kept = np.flatnonzero(rect[:, 1] > rect[:, 0])
    return depth_sort(depth[kept], kept.astype(np.uint32)).astype(np.int64)


def _clip_to_half_turn(box: np.ndarray, mean2d: np.ndarray, period: float) -> None:
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


def _stage1_outputs(n: int) -> tuple[np.ndarray, ...]:
    """Zeroed stage-1 outputs for ``n`` rows: mean2d (2), conic (3), opacity, reach, colour
    (3), depth (float32), box (4) and tile rectangle (4) (int32)."""
    f32 = np.float32
    return (np.zeros((n, 2), f32), np.zeros((n, 3), f32), np.zeros(n, f32), np.zeros(n, f32),
            np.zeros((n, 3), f32), np.zeros(n, f32), np.zeros((n, 4), np.int32),
            np.zeros((n, 4), np.int32))


def describe() -> str:
    """What ``--timings`` prints as the GL renderer of a CPU-rendered frame."""
    return f"none (the CPU renderer: numba, {_threads()} threads)"


#: Splats per part of the projection and the packing when a frame is drawn in pieces
#: (:meth:`CpuRenderer.draw` with ``on_batch``): about 10 ms each here.
PART_SPLATS = 125_000
def _parts(n: int, checkpoint):
    """Yield ``[a, b)`` ranges covering ``n`` rows: one without ``checkpoint``, else parts of
    :data:`PART_SPLATS`, calling ``checkpoint()`` before each but the first."""
    if checkpoint is None or n <= PART_SPLATS:
        yield 0, n
        return
    for i, a in enumerate(range(0, n, PART_SPLATS)):
        if i:
            checkpoint()
        yield a, min(a + PART_SPLATS, n)


def _threads() -> int:
    import numba

    return int(numba.get_num_threads())

