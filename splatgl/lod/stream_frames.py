"""Views of a ``.lod.ply`` streamed from disk under a memory budget (issue 41 item 3).

:class:`StreamFrames` has :class:`~splatgl.lod.frames.LodFrames`' interface (``render_view``,
``render_many``, ``renderer_for``) but never reads the file whole: the cut is chosen over the
lazily read node spheres (:class:`~splatgl.lod.lazy.LazyLod`), exactly as the in-memory cut is
(the same threshold cut with its switch to the leaves, or the budget's search), its nodes are
gathered from the :class:`~splatgl.lod.stream.ResidentSet` (waiting for the chunks not
resident: every frame is exact) and drawn by the quad path over those nodes alone, culled,
sorted and weighted as :class:`~splatgl.lod.source.LodOrder` draws them (:class:`CutRows`).

Positions are taken relative to the anchor stored in the file (the centre of the leaves' 1-99 %
box) where the in-memory path subtracts its node scene's own: the images agree to float32
rounding, and are identical given the same anchor (tests/lod/test_lod_stream.py).  The default
camera and near plane frame the leaves' 1-99 % box the file's header records (:func:`framing_scene`),
as the file read whole is framed; files written before it record no box and are framed by the
1-99 % box of the first level from the top with at least :data:`FRAMING_NODES` nodes.
"""

from __future__ import annotations

import hashlib
import time
from types import SimpleNamespace
from typing import Iterable, Iterator

import numpy as np

from ..cameras.camera import Camera
from ..cameras.view import View
from ..errors import SplatglError
from ..gl.context import create_headless_context, make_current
from ..gl.shaders import ProgramCache
from ..scene.splats import Scene, SplatKind
from ..scene.settings import RendererKind, RenderSettings, SortKey
from ..order import kernels as cull_kernel
from ..order.chunks import keys_order, keys_pairs
from ..order.cull import CullData
from ..order.stage import OrderTimes, cull_for
from ..output.layers import BASE, Layer, RenderOutput
from ..output.under import UnderImage
from ..renderers import registry
from ..renderers.quad import QuadRenderer
from .budget import (CPU_DRAW_RESERVE, StreamPlan, cpu_frame_bytes_per_splat, format_size,
                     release_freed, stream_plan)
from .lazy import LazyLod
from .selection import LodSettings
from .stream import CHUNK_ROWS, LOADERS, LazyChunks, ResidentSet, scene_bytes
from .stream_cut import SPHERE_PAGES_PER_SPLAT, choose_cut, plan_for, tree_cache_need

#: The framing proxy's level: the first from the top with at least this many nodes.
FRAMING_NODES = 4096


def framing_scene(lazy: LazyLod):
    """What the default camera, an orbit and the near plane read of a scene (``robust_bounds``,
    ``robust_radius``, ``anchor``, ``source``, ``count``, ``kind``, ``sh_degree``), and
    ``digest`` (of one coarse level's spheres, the tree's shape and anchor: what a path's frames
    record).  ``robust_bounds`` is the leaves' 1-99 % box the header records, the box that
    frames the file read whole (:func:`splatgl.formats.metadata.apply_framing_box`), so the
    default views agree; for a file written before that box, the 1-99 % box of that coarse
    level's centres."""
    level = 0
    for lv in range(lazy.levels - 1, -1, -1):
        if lazy.level_size(lv) >= FRAMING_NODES:
            level = lv
            break
    centres, radius = lazy.spheres(slice(int(lazy.offsets[level]), int(lazy.offsets[level + 1])))
    if lazy.box is not None:   # the leaves' box, as the file read whole is framed
        lo, hi = lazy.box
    else:                      # written before the box: the proxy's
        pts = centres.T.astype(np.float64) + lazy.anchor
        lo, hi = np.percentile(pts, 1.0, axis=0), np.percentile(pts, 99.0, axis=0)
    digest = hashlib.sha256(b"".join(np.ascontiguousarray(a).tobytes() for a in (
        lazy.offsets, lazy.anchor, centres, radius))).hexdigest()[:20]
    return SimpleNamespace(robust_bounds=(lo, hi), robust_radius=float(0.5 * np.linalg.norm(hi - lo)),
                           anchor=lazy.anchor, source=None, count=lazy.level_size(0),
                           digest=f"lod-{digest}", kind=SplatKind.GAUSSIAN_3D,
                           sh_degree=lazy.nodes(np.zeros(1, np.int64)).sh_degree)


class CutRows:
    """The quad path's rows over a scene holding a cut's nodes in ascending row order, with
    their weights: culled, sorted and weighted as :class:`~splatgl.lod.source.LodOrder` does
    its cut (the same keys, ties in the same order)."""

    def __init__(self, scene, weights: np.ndarray | None, settings: RenderSettings, sort,
                 views: int = 1):
        self.count, self.settings, self.sort = scene.count, settings, sort
        self.weights = weights
        self.times = OrderTimes()
        self.slot_weights: np.ndarray | None = None
        self._views = views
        self._cull = CullData.from_scene(scene)

    def order(self, view: View) -> np.ndarray:
        t0 = time.perf_counter()
        kern = cull_kernel.for_view(self._views)
        ids = np.arange(self.count, dtype=np.int64)
        keys = cull_for(view).rows(self._cull, ids, view, self.settings.antialias, kern,
                                   np.empty(self.count, np.uint64))
        t1 = time.perf_counter()
        order = (keys_order(keys) if self.settings.sort_key is SortKey.EXACT
                 else self.sort(*keys_pairs(keys, self.count)))
        w = self.weights
        self.slot_weights = w[order] if w is not None and (w < 1).any() else None
        self.times = OrderTimes(t1 - t0, time.perf_counter() - t1, 0.0)
        return order


def _drop_nodes(quad: QuadRenderer, scene) -> None:
    """Let the gathered nodes' arrays go once ``quad`` has uploaded them (its storage buffers;
    on a software driver those live in the process too, so keeping both held the cut twice):
    what the renderer reads of its scene after that (kind, SH degree, anchor) stays, as a scene
    of no rows."""
    stub = scene.subset(np.zeros(0, np.int64))
    stub.__dict__["anchor"] = scene.anchor
    quad.scene = quad.programs.scene = quad.buffers.scene = stub


def streamed_kind(kind: RendererKind | str) -> RendererKind:
    """``kind`` as a :class:`RendererKind` a streamed frame draws with
    (:data:`splatgl.renderers.registry.STREAMED`), else one line."""
    kind = RendererKind(kind)
    if kind not in registry.STREAMED:
        raise SplatglError(f"--memory streams a level of detail through the quad path or the "
                           f"cpu renderer, not --renderer {kind.value}")
    return kind


class StreamedViews:
    """What the commands' render loops call on a streamed scene's frames besides
    ``render_view`` (which each kind of stream defines): the views in turn, and the renderer
    that drew the last one."""

    renderer = None

    def render_many(self, scene, cameras: Iterable[Camera], settings=None, kind=None,
                    layers: frozenset[Layer] | None = None) -> Iterator:
        for camera in cameras:
            out = self.render_view(camera, BASE if layers is None else layers)
            yield out.rgba if layers is None else out

    def renderer_for(self, scene=None, settings=None, kind=None):
        return self.renderer


class StreamFrames(StreamedViews):
    """Views of the ``.lod.ply`` at ``path`` through the cut ``lod``, streamed with the whole
    process under ``memory`` bytes (see the module doc); owns its context (a context manager).
    ``framing``: what frames views (default :func:`framing_scene`); ``plan``: how the budget
    is shared (default :func:`splatgl.lod.stream_cut.plan_for`, measured once the context
    exists): the chunk cache holds ``plan.cache`` bytes, a frame at most ``plan.cap`` splats
    (a coarser cut where the view's asks for more, said once in :attr:`capped`).  ``kind``:
    the quad path (default) or the CPU renderer (no GL context; the cut's opacity weights
    applied to the nodes, and its own bytes a splat in the plan:
    :func:`splatgl.lod.budget.cpu_frame_bytes_per_splat`)."""

    stereo_refusal = "--stereo and --memory (streaming a level of detail) cannot be combined yet"

    def __init__(self, path, settings: RenderSettings, lod: LodSettings, memory: int,
                 chunk_rows: int = CHUNK_ROWS, threads: int = LOADERS, framing=None,
                 plan: StreamPlan | None = None, kind: RendererKind = registry.DEFAULT_RENDERER):
        self.settings, self.lod, self.memory = settings, lod, int(memory)
        self.kind = streamed_kind(kind)
        self.lazy = LazyLod(path)
        self.ctx = self.renderer = self.resident = None
        try:
            self.framing = framing if framing is not None else framing_scene(self.lazy)
            release_freed()
            if registry.entry(self.kind).gl:   # the quad path
                self.ctx = create_headless_context()
                self.programs = ProgramCache(self.ctx)
            else:   # its compiled kernels (and numba) before the plan measures what is held
                from ..renderers.cpu import prepare

                prepare()
            chunks = LazyChunks(self.lazy, chunk_rows)
            need = tree_cache_need(chunks, self.lazy.offsets, threads)
            self.plan = plan or (
                plan_for(self.lazy, self.memory, settings.gpu_storage, need)
                if self.ctx is not None else
                stream_plan(self.memory, cpu_frame_bytes_per_splat(
                    self.lazy.nodes(np.zeros(1, np.int64)).sh.shape[1]), need,
                    reserve=CPU_DRAW_RESERVE))
            self.resident = ResidentSet(chunks, self.plan.cache, self.lazy.offsets,
                                        self.lazy.branching, threads)
        except BaseException:
            self.close()
            raise
        self.last_cut_nodes = 0
        self.last_cut_s = 0.0
        #: The first view's line saying the memory bound made its cut coarser (None: none
        #: was); :attr:`capped_views` counts such views.
        self.capped: str | None = None
        self.capped_views = 0
        #: Bytes of the last frame's gathered scene (its nodes, held once).
        self.last_gathered_bytes = 0
        self._views = 0

    @property
    def nodes(self):
        return self.framing

    def render_view(self, camera: Camera, layers: frozenset[Layer] = BASE,
                    under: UnderImage | None = None) -> RenderOutput:
        """One exact view: waits for every chunk its cut needs."""
        if self.ctx is not None:
            make_current(self.ctx)
        if self.renderer is not None:   # the last frame's buffers go before this one's cut
            self.renderer.release()
            self.renderer = None
            release_freed()
        view = View.of(camera, self.settings, self.framing)
        t0 = time.perf_counter()
        choice = choose_cut(self.lazy, view.camera, self.lod, self.plan.cap)
        self.lazy.trim_spheres(SPHERE_PAGES_PER_SPLAT * 16 * self.plan.cap)
        self.last_cut_s = time.perf_counter() - t0
        self.last_cut_nodes = int(choice.rows.size)
        if choice.capped is not None:
            self.capped_views += 1
            self.capped = self.capped or choice.capped
        scene = self.resident.gather(choice.rows)
        self.last_gathered_bytes = scene_bytes(scene)
        scene.__dict__["anchor"] = np.asarray(self.framing.anchor, np.float64)  # cached_property
        self._views += 1
        if self.ctx is None:   # the CPU renderer
            return self._render_cpu(view, scene, choice.weights, layers, under)
        rows = CutRows(scene, choice.weights, self.settings, None, self._views)
        quad = QuadRenderer(self.ctx, scene, self.settings, self.programs, rows=rows)
        if self.lod.band > 1.0 and not quad.uses_prepass:
            quad.release()
            raise SplatglError(f"--lod-blend {self.lod.band:g} weights opacities in the compute "
                               "pre-pass: use --preprocess compute (the default), or --lod-blend 1")
        rows.sort = quad.sort
        self.renderer = quad
        _drop_nodes(quad, scene)   # now in the renderer's buffers and the cull's data
        del scene
        release_freed()
        if under is None:
            return quad.render(view, layers)
        return quad.render(view, layers, under=view.geometry(under))

    def _render_cpu(self, view: View, scene, weights, layers, under) -> RenderOutput:
        """The CPU renderer's frame of the gathered cut: its weights applied to the nodes'
        opacities (:func:`splatgl.lod.selection.blended_scene`'s rule, as the in-memory cut's
        NumPy twin), drawn as the CPU renderer draws that scene in memory (every row projected:
        the same image without building the cull's data)."""
        from ..renderers.cpu import CpuRenderer

        if weights is not None and (weights < 1).any():
            o = 1.0 - (1.0 - scene.opacities.astype(np.float64)) ** weights.astype(np.float64)
            anchor = scene.anchor
            scene = Scene.from_activated(scene.means, scene.quats, scene.scales, o, scene.sh,
                                         scene.kind)
            scene.__dict__["anchor"] = anchor
        self.renderer = CpuRenderer(scene, self.settings, cull=False)   # the cut is in view
        del scene
        if under is None:
            return self.renderer.render(view, layers)
        return self.renderer.render(view, layers, under=view.geometry(under))

    def summary(self) -> str:
        """Resident memory and chunks, the bytes read from the file and the memory bound's
        cap (for ``--timings``)."""
        capped = f", {self.capped_views} of {self._views} views capped" if self.capped_views else ""
        return (f"{self.resident.stats.summary(self.plan.cache)}; "
                f"{format_size(self.lazy.bytes_read)} read; frame at most {self.plan.cap:,} "
                f"splats{capped}")

    def close(self) -> None:
        if self.resident is not None:
            self.resident.close()
        if self.ctx is not None:
            make_current(self.ctx)
            if self.renderer is not None:
                self.renderer.release()
            self.ctx.release()
            self.ctx = None
        self.renderer = None
        self.lazy.close()

    def __enter__(self) -> "StreamFrames":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def render_streamed(path, camera: Camera, settings: RenderSettings, lod: LodSettings, memory: int,
                    layers: frozenset[Layer] = BASE, under: UnderImage | None = None,
                    framing=None, plan: StreamPlan | None = None,
                    kind: RendererKind = registry.DEFAULT_RENDERER
                    ) -> tuple[RenderOutput, SimpleNamespace, str]:
    """One exact view of the ``.lod.ply`` at ``path`` streamed under ``memory`` bytes: (the
    ``layers``, times as :func:`splatgl.lod.frames.render_lod` gives them plus ``streaming``
    (:meth:`StreamFrames.summary`) and ``capped`` (:attr:`StreamFrames.capped`), the GL
    renderer's name, or the CPU renderer's :func:`splatgl.renderers.registry.describe`)."""
    with StreamFrames(path, settings, lod, memory, framing=framing, plan=plan,
                      kind=kind) as frames:
        gl_name = registry.describe(frames.kind, frames.ctx)
        out = frames.render_view(camera, layers, under)
        times = SimpleNamespace(**vars(frames.renderer.last_times), cut_nodes=frames.last_cut_nodes,
                                cut=frames.last_cut_s, streaming=frames.summary(),
                                capped=frames.capped)
    return out, times, gl_name
