"""The CPU renderer (``--renderer cpu``): the reference's per-tile algorithm, compiled with numba.

On a machine without a GPU, OpenGL is llvmpipe, and the quad path pays llvmpipe's cost for
every quad and fragment (about 1 us a quad in its single-threaded front end, and blending in
a float target).  This renderer skips OpenGL: the reference's five stages (project, key
emission, sort, tile ranges, per-tile blending) run as three compiled passes
(:mod:`splatgl.renderers._cpu_project`, :mod:`splatgl.renderers._cpu_raster`), the tiles shared by every core, and each splat
evaluated only on the pixels of its box where it can reach alpha 1/255.  Its image is the
reference's own algorithm in float32, so it agrees with :func:`splatgl.reference.render_reference`
more closely than the quad path does (tests/renderers/test_cpu_renderer.py states the tolerances).
docs/interactive.md measures it against the quad path and limacv's viewer.

It needs numba (the ``fast`` extra) and draws 3DGS splats with colour, alpha and the depth
layer, under the inria rules, with the global order.  Pinhole cameras project in a compiled
pass too; every other camera model the reference draws (fisheye, equirectangular, OpenCV
distortion, orthographic) projects with the reference's NumPy stage 1, which is slower.
Only the splats the view's cull keeps are projected (:meth:`CpuRenderer.kept_rows`: the table
:data:`splatgl.order.stage.CULLS`, which the scene and level-of-detail orders run too, in its
conservative mode); the image is the one projecting every splat gives.
"""

from __future__ import annotations

import importlib
import importlib.util
import time
from dataclasses import dataclass
from types import SimpleNamespace

import numpy as np

from ..cameras.view import View
from ..scene.splats import Scene
from ..scene.settings import RendererKind, RenderSettings
from ..output.layers import BASE, Layer, RenderOutput
from ..output.under import UnderLayer
from ..progress import ProgressCallback, default_progress
from ..cameras.equirect import WRAP_FLAG
from ..constants import LOW_PASS
from ..order.chunks import ChunkedCull
from ..order.sort import depth_sort
from ..order.stage import cull_for
from ..reference.stages import tile_grid
from ._cpu_stage1 import Stage1
from .options import CpuOptions
from .registry import RENDERERS, Registered, check
from .quad_layers import composite

#: The layers this renderer draws (its entry in :mod:`splatgl.renderers.registry`).
LAYERS = RENDERERS[RendererKind.CPU].layers


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

    @property
    def ordering(self) -> float:
        return self.project + self.sort

    @property
    def drawing(self) -> float:
        return self.bin + self.rasterize

    def summary(self, count: int) -> str:
        return f"splats {count:,}, {self.n_keys:,} tile entries"


#: The compiled stages, once loaded (:func:`prepare`).
_LOADED: SimpleNamespace | None = None
#: Whether :func:`prepare` finished in this process (every kernel compiled or loaded).
_READY = False
#: The kernels numba caches on disk (``cache=True``), by module.
_CACHED_KERNELS = {"splatgl.renderers._cpu_project": ("project_pinhole", "project_model"),
                   "splatgl.renderers._cpu_raster": ("pack", "bin_tiles", "rasterize")}


def kernels_ready() -> bool:
    """Whether the kernels are ready without compiling: loaded in this process, or each held
    by numba's on-disk cache for this source and numba (loading them then takes about 0.5 s,
    not the 25 s of a compile).  False where numba is missing.  ``--renderer auto`` draws with
    this renderer only when they are (:mod:`splatgl.renderers.auto`)."""
    if _READY:
        return True
    if importlib.util.find_spec("numba") is None:
        return False
    try:
        for module, names in _CACHED_KERNELS.items():
            mod = importlib.import_module(module)
            for name in names:
                if not getattr(mod, name)._cache._cache_file._load_index():
                    return False     # never compiled here, or stale (source or numba changed)
    except (AttributeError, OSError, EOFError, ValueError):   # numba's internals moved
        return False
    return True


def prepare(progress: ProgressCallback | None = None) -> None:
    """Load the compiled kernels now, once per process: numba compiles them on the first use
    after an install (about 25 s on the 2-core AVX2 machine; nothing was drawn or said
    meanwhile) and loads them from its cache afterwards (about 0.5 s).  A tiny scene is drawn
    through a pinhole and a fisheye camera, so that every kernel signature a frame calls is
    ready, and ``progress`` (default: the stderr meter on a terminal,
    :func:`splatgl.progress.default_progress`) hears of it.  Commands call it before work that
    should not stall, such as opening a window; the first renderer calls it otherwise."""
    _kernels(progress)


def _kernels(progress: ProgressCallback | None = None) -> SimpleNamespace:
    """The compiled stages (:mod:`._cpu_project`, :mod:`._cpu_raster`), ready (:func:`prepare`)."""
    global _LOADED, _READY
    check(RendererKind.CPU)           # numba, the fast extra
    if _LOADED is None:
        project_mod = importlib.import_module("splatgl.renderers._cpu_project")
        raster_mod = importlib.import_module("splatgl.renderers._cpu_raster")
        _LOADED = SimpleNamespace(project_pinhole=project_mod.project_pinhole,
                                  project_model=project_mod.project_model,
                                  pack=raster_mod.pack, bin_tiles=raster_mod.bin_tiles,
                                  rasterize=raster_mod.rasterize, REC_SIZE=raster_mod.REC_SIZE)
        if progress is None:   # the terminal's meter only for a compile (a load: about 0.5 s)
            progress = None if kernels_ready() else default_progress()
        _warm_up(progress)
    _READY = True
    return _LOADED


def _warm_up(progress: ProgressCallback | None) -> None:
    """Draw 16 splats through a 32 x 32 pinhole camera, then a fisheye (every kernel, with the
    argument types a real frame passes: compiled or loaded from numba's cache now)."""
    from ..cameras.camera import Camera
    from ..cameras.fisheye import Fisheye

    what = "preparing the CPU renderer (compiled on first use: about half a minute)"
    rng = np.random.default_rng(0)
    means = rng.normal(0.0, 0.3, (16, 3)) + [0.0, 0.0, 3.0]
    scene = Scene(means, rng.normal(size=(16, 4)), rng.normal(-2.5, 0.3, (16, 3)),
                  rng.normal(1.0, 1.0, 16), rng.normal(0.0, 0.3, (16, 4, 3)))
    options = CpuOptions()
    renderer = CpuRenderer(scene, options)
    cameras = (Camera.from_fov(32, 32, 60.0), Camera.of_model(Fisheye, 32, 32, 180.0))
    for i, camera in enumerate(cameras):
        if progress is not None:
            progress(i, len(cameras), what)
        renderer.draw(View.of(camera, options, scene), with_depth=True)
    if progress is not None:
        progress(len(cameras), len(cameras), what)


def tile_order(n_tiles: int, threads: int) -> np.ndarray:
    """Tile ids in the order the compiled loop hands them out: its threads take contiguous
    runs, so the ids are interleaved (thread c gets c, c + n, c + 2n, ...), which spreads busy
    and empty parts of the image over all of them.  Measured against the plain order (blend
    stage, 8 views of the flight's orbit twice, 2 cores): the plain order took 0.98x as long
    on donut, 1.09x on biker and 1.27x on guitar, a small object in the middle of the view."""
    threads = max(1, threads)
    return np.concatenate([np.arange(c, n_tiles, threads, dtype=np.int64) for c in range(threads)])


class CpuRenderer(Registered):
    """Renders one scene on the CPU; reuse it across views.

    Attributes: ``scene``, ``options`` (:class:`CpuOptions`), ``last_times`` (:class:`CpuTimes`
    of the last frame, or None).  :meth:`render` has the GPU renderers' signature; :meth:`release` frees
    nothing (no GL objects) and is there for :class:`splatgl.api.Renderer`'s cache.  ``cull``
    False: every row is projected (:meth:`kept_rows` None), for a scene drawn once whose rows
    are already chosen in view (a streamed level of detail's cut), where building the cull's
    chunked data cost more than it saved (0.86 s of a 1M cut's 1.27 s projection); the same image.
    """

    kind = RendererKind.CPU

    def __init__(self, scene: Scene, options: CpuOptions | RenderSettings, cull: bool = True):
        options = self.own(options)
        self.cull = cull
        check(self.kind, scene=scene)
        self.k = _kernels()
        self.scene = scene
        self.last_times: CpuTimes | None = None
        self.stage1 = Stage1(scene, options, self.k)
        self._tiles: dict[tuple, list[np.ndarray]] = {}     # the bands of each grid
        self._rec = np.empty((0, self.k.REC_SIZE), np.float32)   # the splat records, reused
        self._chunks: ChunkedCull | None = None   # the view's cull's data, on the first frame

    def render(self, view: View, layers: frozenset[Layer] = BASE,
               under: UnderLayer | None = None) -> RenderOutput:
        """The ``layers`` of one view (colour and alpha; depth when asked): RGB = C + (1 - A)
        background, alpha = A, as the quad path composites it; row 0 is the top."""
        layers = frozenset(layers)
        check(self.kind, layers=layers, under=under is not None)
        rgba, depth = self.draw(view, Layer.DEPTH in layers)
        if any(self.options.background):
            rgba = composite(rgba, self.options.background)
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

        rows = self.kept_rows(view)
        parts = _parts(self.scene.count if rows is None else rows.size, checkpoint)
        project = self.stage1.pinhole if view.frustum.pinhole else self.stage1.model
        mean2d, conic, opacity, reach, color, z, box, rect = project(view, parts, rows)
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

    def kept_rows(self, view: View) -> np.ndarray | None:
        """(K,) int64 scene rows, ascending, that the view's cull keeps (:func:`cull_for`: the
        table the scene order and the level-of-detail order run), or None (every row).  Only
        those rows are projected; the rest could not have had a tile rectangle, so the image
        is the one every row gives.  None for a draft's smaller low pass (the peak bound
        assumes the full one) and a view not anchored at the scene's anchor (the cull data's)."""
        if (not self.cull or view.low_pass is not None and view.low_pass < LOW_PASS
                or not np.array_equal(view.anchor, self.scene.anchor)):
            return None
        if self._chunks is None:
            self._chunks = ChunkedCull.from_scene(self.scene)
        keys = cull_for(view).scene(self._chunks, view, self.stage1.antialias, ewa=True)
        kept = np.zeros(self.scene.count, np.bool_)
        kept[(keys & np.uint64(0xFFFFFFFF)).astype(np.uint32) & ~WRAP_FLAG] = True  # seam copies
        return np.flatnonzero(kept)

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

