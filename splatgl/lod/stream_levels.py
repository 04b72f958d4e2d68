"""PlayCanvas Streamed SOG (``lod-meta.json``) and XGrids LCC (``meta.lcc``) streamed under a
memory budget, as a ``.lod.ply`` is (issue 41 items 3 and 4): ``render``, ``render --path``,
``eval`` and ``bench`` with ``--memory`` (:class:`ChunkedFrames`) and ``view --memory``
(:class:`splatgl.lod.stream_levels_view.ChunkedScene`).

The structure (:func:`read_structure`: the manifest and index only) gives the chunks and, per
chunk and level, its splats.  :class:`ChunkLevels` makes each (chunk, level) holding splats one
chunk of the :class:`~splatgl.lod.stream.ResidentSet` (loaded on its background threads, the
least recently used evicted; a load decodes that chunk's rows of that level:
``structure.load(level, [chunk], environment=False)``; a Streamed SOG's decodes the SOG unit
holding them, kept for its sibling chunks: :class:`LastUnit`).  Each view chooses a level per chunk by screen-space error under the splat budget
(:func:`splatgl.lod.level_cut.choose_levels`), or the level ``--lod-level`` gives; a headless
frame waits for its chunks and draws them, in the file's chunk order followed by the
environment (loaded once, counted in the budget), with the renderer asked for: the image of
those chunks read whole.  With a level given and every chunk in view that is the level read whole
(``structure.load(level)``), given the same anchor and near plane (tests/lod/test_stream_levels.py).
The default camera frames the box the manifest records where ``splatgl lod`` wrote it (the one
the file read whole frames), else the boxes of the chunks (:func:`framing_of`), not the splats'
1-99 % box as for a scene read whole.
"""

from __future__ import annotations

import hashlib
import threading
import time
from pathlib import Path
from types import SimpleNamespace

import numpy as np

from ..cameras.camera import Camera
from ..cameras.view import View
from ..errors import SplatglError
from ..gl.context import create_headless_context, make_current
from ..gl.shaders import ProgramCache
from ..output.layers import BASE, Layer, RenderOutput
from ..output.under import UnderImage
from ..renderers import registry
from ..scene.settings import RendererKind, RenderSettings
from ..scene.splats import SplatKind
from ..gl.storage import gpu_bytes_per_splat
from ..scene.settings import GpuStorage
from .budget import (CPU_DRAW_RESERVE, DRAW_RESERVE, StreamPlan, cpu_frame_bytes_per_splat,
                     format_size, frame_bytes_per_splat, release_freed, stream_plan)
from .level_cut import NOT_DRAWN, ChunkTable, cap_levels, choose_levels
from .selection import LodSettings
from .stream import LOADERS, ResidentSet, concatenate, scene_bytes
from .stream_frames import StreamedViews

#: The format names (``formats.detect_format``) streamed here.
CHUNKED_FORMATS = ("streamed-sog", "lcc")


def is_chunked(path) -> bool:
    """Whether ``path`` is a Streamed SOG ``lod-meta.json`` or an LCC ``meta.lcc`` (by content)."""
    from ..formats import lcc, streamed_sog

    try:
        with open(path, "rb") as fh:
            head = fh.read(1 << 16)
    except (OSError, TypeError):
        return False
    return streamed_sog.sniff(head) or lcc.sniff(head)


def read_structure(path):
    """The structure (levels, chunks) of the Streamed SOG or LCC scene at ``path``."""
    from ..formats import lcc, streamed_sog

    with open(path, "rb") as fh:
        head = fh.read(1 << 16)
    return (streamed_sog if streamed_sog.sniff(head) else lcc).read_structure(path)


def check_level(structure, level: int | None) -> None:
    """Refuse ``--lod-level`` past the file's levels (one line)."""
    if level is not None and not 0 <= level < structure.levels:
        raise SplatglError(f"--lod-level {level}: {structure.path} has {structure.levels} "
                           f"levels (0-{structure.levels - 1}, 0 the finest)")


class LastUnit:
    """The SOG unit a Streamed SOG's loads decoded last (the chunks of a unit are its row ranges:
    siblings load from it instead of decoding it again); one decode at a time, thread-safe.  It
    is held beyond the chunk budget, as a load's decode is (one unit, at most about 256K splats
    in splatgl's files)."""

    def __init__(self, structure):
        self.structure = structure
        self._lock = threading.Lock()
        self._last: tuple[int, object] | None = None

    def rows(self, chunk: int, level: int):
        file = self.structure.chunks[chunk].lods[level][0]
        with self._lock:
            if self._last is None or self._last[0] != file:
                self._last = None   # freed before the next decode
                self._last = (file, self.structure.unit(file))
            unit = self._last[1]
        return self.structure.rows_of(unit, chunk, level)


class ChunkLevels:
    """Each (chunk, level) of ``structure`` holding splats, as one resident-set chunk (``count``,
    ``estimate(i)``, ``load(i)``; ``key[(chunk, level)]`` its index); decoded bytes a row
    measured on the smallest (:attr:`sample`: that load).  A Streamed SOG's chunks load through
    :class:`LastUnit`."""

    rows = 1   # no tree rows

    def __init__(self, structure):
        self.structure = structure
        self.units = LastUnit(structure) if hasattr(structure, "rows_of") else None
        self.pairs = [(c, level) for c, chunk in enumerate(structure.chunks)
                      for level in range(structure.levels) if chunk.count(level) > 0]
        if not self.pairs:
            raise SplatglError(f"{structure.path}: no level holds splats")
        self.key = {pair: i for i, pair in enumerate(self.pairs)}
        self.counts = [structure.chunks[c].count(level) for c, level in self.pairs]
        self.count = len(self.pairs)
        self.nodes = sum(self.counts)
        small = min(range(self.count), key=self.counts.__getitem__)
        self.sample = self.load(small)
        self.row_bytes = -(-scene_bytes(self.sample) // self.counts[small])

    def estimate(self, i: int) -> int:
        return self.counts[i] * self.row_bytes

    def load(self, i: int):
        chunk, level = self.pairs[i]
        if self.units is not None:
            return self.units.rows(chunk, level)
        return self.structure.load(level, [chunk], environment=False)


def framing_of(structure, sample) -> SimpleNamespace:
    """What frames the views (as :func:`splatgl.lod.stream_frames.framing_scene` gives it):
    the framing box the manifest records (a Streamed SOG ``splatgl lod`` wrote: the box that
    frames the file read whole, :func:`splatgl.formats.metadata.apply_framing_box`), else the
    box of the chunks holding level-0 splats (every chunk where level 0 has none); its centre
    the anchor; ``sample``: a decoded chunk (the SH degree)."""
    if structure.box is not None:   # recorded by splatgl lod: the file's framing read whole too
        lo, hi = structure.box
    else:
        boxes = [(c.bound_min, c.bound_max) for c in structure.chunks if c.count(0) > 0] or [
            (c.bound_min, c.bound_max) for c in structure.chunks]
        lo = np.min([b[0] for b in boxes], 0).astype(np.float64)
        hi = np.max([b[1] for b in boxes], 0).astype(np.float64)
    anchor = (0.5 * (lo + hi)).astype(np.float32).astype(np.float64)
    digest = hashlib.sha256(repr((structure.levels, structure.counts, lo.tolist(), hi.tolist(),
                                  len(structure.chunks))).encode()).hexdigest()[:20]
    return SimpleNamespace(robust_bounds=(lo, hi), robust_radius=float(0.5 * np.linalg.norm(hi - lo)),
                           anchor=anchor, source=None, count=int(structure.counts[0]),
                           digest=f"chunked-{digest}", kind=SplatKind.GAUSSIAN_3D,
                           sh_degree=sample.sh_degree)


def framing_at(path) -> SimpleNamespace:
    """:func:`framing_of` the Streamed SOG or LCC at ``path`` (its manifest and one chunk read)."""
    structure = read_structure(path)
    return framing_of(structure, ChunkLevels(structure).sample)


class ChunkedStream:
    """What the headless frames and the viewer share: the structure, the chunks, the framing,
    the environment and the :class:`ResidentSet`.  ``memory`` is shared as a ``.lod.ply``
    stream shares it (``plan``: default :func:`splatgl.lod.budget.stream_plan`, measured now:
    call it once the GL context exists): the chunks and the environment hold ``plan.cache``
    bytes, a frame at most ``plan.cap`` splats (levels coarsened to fit, said once in
    :attr:`capped`).  ``pinned``: the coarsest level of every chunk is loaded at once and never
    evicted (the viewer's stand-ins), and a view draws at most the splats the chunks' share
    holds besides them (the viewer keeps a view's chunks resident to complete it)."""

    def __init__(self, path, lod: LodSettings, memory: int, level: int | None = None,
                 threads: int = LOADERS, pinned: bool = False, on_loaded=None, framing=None,
                 plan: StreamPlan | None = None, storage: GpuStorage = GpuStorage.FLOAT32,
                 cpu: bool = False):
        self.path, self.lod, self.level, self.memory = Path(path), lod, level, int(memory)
        self.structure = read_structure(path)
        check_level(self.structure, level)
        self.chunks = ChunkLevels(self.structure)
        sample, self.chunks.sample = self.chunks.sample, None
        self.framing = framing if framing is not None else framing_of(self.structure, sample)
        self.table = ChunkTable.of(self.structure, self.framing.anchor)
        self.environment = self._load_environment()
        env_bytes = 0 if self.environment is None else scene_bytes(self.environment)
        coarsest = [self.chunks.key[(c, int(np.flatnonzero(row)[-1]))]
                    for c, row in enumerate(self.table.counts > 0) if row.any()]
        need = env_bytes + max(1, threads) * max(map(self.chunks.estimate, range(self.chunks.count)))
        need += sum(map(self.chunks.estimate, coarsest)) if pinned else 0
        release_freed()
        self.plan = plan or (stream_plan(   # cpu: the CPU renderer draws (its own bytes a splat)
            self.memory, cpu_frame_bytes_per_splat(sample.sh.shape[1]), need,
            reserve=CPU_DRAW_RESERVE) if cpu else stream_plan(self.memory, frame_bytes_per_splat(
                sample.sh.shape[1], gpu_bytes_per_splat(storage, sample.sh_degree)), need,
                reserve=DRAW_RESERVE))
        if env_bytes >= self.plan.cache:
            raise SplatglError(f"--memory {format_size(self.memory)} is too small to stream "
                               f"{self.path.name}: its environment alone is {format_size(env_bytes)}"
                               f" of the chunks' {format_size(self.plan.cache)}")
        self.cap = max(1, self.plan.cap - (0 if self.environment is None else self.environment.count))
        self.capped: str | None = None
        self.capped_views = self.views = 0
        self.resident = ResidentSet(self.chunks, self.plan.cache - env_bytes, None, 1, threads,
                                    on_loaded, pinned=coarsest if pinned else None)
        if pinned:   # the viewer: a view's chunks must all fit to complete (they are kept)
            self.resident.collect(sorted(coarsest), lambda i, scene: None)
            room = (self.plan.cache - need) // self.chunks.row_bytes
            self.cap = max(1, min(self.cap, int(room)))

    def _load_environment(self):
        if not self.structure.has_environment:
            return None
        return self.structure.load(0, [], environment=True)

    def view_camera(self, camera: Camera, settings: RenderSettings) -> Camera:
        return View.of(camera, settings, self.framing).camera   # the scene transform applied

    def choose(self, camera: Camera, lod: LodSettings | None = None) -> np.ndarray:
        """(K,) the level of each chunk for ``camera`` (the transformed one), coarsened to the
        frame's cap where the choice asks for more splats."""
        levels = choose_levels(self.table, camera, lod or self.lod, self.level)
        self.views += 1
        asked = self.table.splats(levels)
        if asked <= self.cap:
            return levels
        levels = cap_levels(self.table, camera, levels, self.cap)
        self.capped_views += 1
        if self.capped is None:
            what = (f"--lod-level {self.level}" if self.level is not None
                    else f"--lod-threshold {(lod or self.lod).threshold_px:g} px")
            self.capped = (f"the memory bound made the levels coarser than {what} asked: "
                           f"{self.table.splats(levels):,} of {asked:,} splats (the frame holds "
                           f"at most {self.cap:,} splats)")
        return levels

    def ids(self, levels: np.ndarray) -> list[int]:
        """The resident-set chunks of a choice, in the file's chunk order."""
        return [self.chunks.key[(c, int(levels[c]))] for c in np.flatnonzero(levels != NOT_DRAWN)]

    def scene_of(self, ids: list[int]):
        """The chunks ``ids`` (waiting for those not resident) and the environment, one scene
        anchored at the framing's anchor."""
        parts = self.resident.collect(ids, lambda i, scene: scene)
        order = [parts[i] for i in ids]
        if self.environment is not None:
            order.append(self.environment)
        if not order:   # nothing in view: one splat of the coarsest chunk, fully transparent
            scene = self.chunks.load(self.chunks.key[next(iter(self.chunks.pairs))]).subset(
                np.zeros(1, np.int64))
            scene = type(scene)(scene.means, scene.quats, scene.log_scales,
                                np.full(1, -1e4, scene.opacity_logits.dtype), scene.sh, scene.kind)
        else:
            scene = concatenate(order)
        scene.__dict__["anchor"] = np.asarray(self.framing.anchor, np.float64)  # cached_property
        return scene

    def summary(self) -> str:
        where = "" if self.level is None else f", --lod-level {self.level}"
        capped = f", {self.capped_views} of {self.views} views capped" if self.capped_views else ""
        chunks = len(self.structure.chunks)
        return (f"{self.resident.stats.summary(self.plan.cache)}; {self.chunks.count} chunk "
                f"levels of {chunks} chunk{'s' if chunks != 1 else ''} x {self.structure.levels} "
                f"levels{where}; frame at most {self.cap:,} splats{capped}")

    def close(self) -> None:
        self.resident.close()


class ChunkedFrames(StreamedViews):
    """Views of the Streamed SOG or LCC at ``path`` streamed under ``memory`` bytes, each
    waiting for its chunks (see the module doc), drawn by renderer ``kind``; the interface of
    :class:`splatgl.lod.stream_frames.StreamFrames` (``render_view``, ``render_many``,
    ``renderer_for``, ``summary``, ``framing``); owns its context (a context manager)."""

    stereo_refusal = "--stereo and --memory (streaming a level of detail) cannot be combined yet"

    def __init__(self, path, settings: RenderSettings, lod: LodSettings, memory: int,
                 level: int | None = None, kind: RendererKind = registry.DEFAULT_RENDERER,
                 threads: int = LOADERS, framing=None, plan: StreamPlan | None = None):
        self.settings, self.lod, self.memory, self.kind = settings, lod, int(memory), kind
        self.ctx = self.renderer = self.programs = self.stream = None
        self._ids: list[int] | None = None
        self.last_cut_nodes = 0
        self.last_cut_s = self.last_gather_s = 0.0   # the level choice; reading the chunks
        try:
            if registry.entry(kind).gl:   # first: the plan measures what the process holds
                self.ctx = create_headless_context()
                self.programs = ProgramCache(self.ctx)
            elif RendererKind(kind) in registry.STREAMED:   # the CPU renderer: its kernels
                # (and numba) loaded before the plan measures what the process holds
                from ..renderers.cpu import prepare

                prepare()
            self.stream = ChunkedStream(path, lod, memory, level, threads, framing=framing,
                                        plan=plan, storage=settings.gpu_storage,
                                        cpu=self.ctx is None and RendererKind(kind) in
                                        registry.STREAMED)
        except BaseException:
            self.close()
            raise
        self.framing, self.resident = self.stream.framing, self.stream.resident

    @property
    def capped(self) -> str | None:
        """One line where the memory bound made a view's levels coarser than asked, else None."""
        return self.stream.capped

    @property
    def nodes(self):
        return self.framing

    def render_view(self, camera: Camera, layers: frozenset[Layer] = BASE,
                    under: UnderImage | None = None) -> RenderOutput:
        """One exact view: waits for every chunk its levels need."""
        view = View.of(camera, self.settings, self.framing)
        t0 = time.perf_counter()
        ids = self.stream.ids(self.stream.choose(view.camera))
        t1 = time.perf_counter()
        self.last_cut_s, self.last_gather_s = t1 - t0, 0.0
        if ids != self._ids or self.renderer is None:   # the same chunks: the upload is kept
            scene = self.stream.scene_of(ids)
            self.last_gather_s = time.perf_counter() - t1
            self._release()
            if self.ctx is not None:
                make_current(self.ctx)
            self.renderer = registry.make(self.kind, scene, self.settings, self.ctx,
                                          self.programs)
            self._ids = ids
            self.last_cut_nodes = scene.count
        elif self.ctx is not None:
            make_current(self.ctx)
        if under is None:
            return self.renderer.render(view, layers)
        return self.renderer.render(view, layers, under=view.geometry(under))

    def summary(self) -> str:
        """Resident memory and chunks (for ``--timings``)."""
        return self.stream.summary()

    def _release(self) -> None:
        if self.renderer is not None:
            if self.ctx is not None:
                make_current(self.ctx)
            self.renderer.release()
            self.renderer = None

    def close(self) -> None:
        if self.stream is not None:
            self.stream.close()
        self._release()
        if self.ctx is not None:
            self.ctx.release()
            self.ctx = None

    def __enter__(self) -> "ChunkedFrames":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def render_chunked(path, camera: Camera, settings: RenderSettings, lod: LodSettings, memory: int,
                   level: int | None = None, layers: frozenset[Layer] = BASE,
                   under: UnderImage | None = None, framing=None,
                   kind: RendererKind = registry.DEFAULT_RENDERER):
    """One exact view of the Streamed SOG or LCC at ``path`` streamed under ``memory`` bytes:
    (the ``layers``, times as :func:`splatgl.lod.stream_frames.render_streamed` gives them, the
    GL renderer's name, or what drew without one: :func:`splatgl.renderers.registry.describe`)."""
    with ChunkedFrames(path, settings, lod, memory, level, kind, framing=framing) as frames:
        gl_name = registry.describe(kind, frames.ctx)
        out = frames.render_view(camera, layers, under)
        times = SimpleNamespace(**vars(frames.renderer.last_times), cut_nodes=frames.last_cut_nodes,
                                cut=frames.last_cut_s, gather=frames.last_gather_s,
                                streaming=frames.summary(), capped=frames.capped)
    return out, times, gl_name
