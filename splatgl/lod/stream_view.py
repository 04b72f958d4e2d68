"""The viewer's scene of a level of detail streamed from disk (``splatgl view --memory``, issue 41
item 3): what is resident now, refined as chunks arrive.

:meth:`StreamedScene.scene_for` never waits: it chooses the view's cut (as a path frame does,
:func:`splatgl.lod.stream_frames.choose_cut`), draws the nodes whose chunks are resident and,
for the others, their nearest resident ancestors
(:meth:`splatgl.lod.stream.ResidentSet.resident_cut`), and requests the missing chunks;
``on_change`` (the viewer wakes its loop) is called as each arrives and :attr:`generation`
counts them, so the viewer draws again and the image refines until :attr:`complete`: then it is
the view's exact cut.  A view's own cut whose chunks cannot all be resident at once
(:meth:`~splatgl.lod.stream.ResidentSet.fits`: it touches more chunk bytes than the cache holds
besides the pinned levels) would never complete that way: it is gathered as a headless frame is
(:meth:`~splatgl.lod.stream.ResidentSet.gather`, chunks copied out as they arrive) on a
background thread, one at a time, abandoned when another cut is asked for, while the resident
ancestors are drawn; only from a view's second draw on (at rest: a moving frame does not gather,
it moves the generation on so that the next draw of its view does); once it is gathered the
generation moves on and the next draw of that cut is the exact one (the gathered scene is the
frame's share of the memory plan).
:meth:`exact_scene` waits for every chunk (screenshots).  A cut's opacity
weights are applied to the nodes' opacities (:func:`splatgl.lod.selection.blended_scene`'s rule),
so any renderer draws the scene.
"""

from __future__ import annotations

import threading

import numpy as np

from ..cameras.camera import Camera
from ..cameras.view import View
from ..scene.splats import Scene
from ..scene.settings import RenderSettings
from .lazy import LazyLod
from .selection import LodSettings
from .budget import StreamPlan, release_freed
from .stream import CHUNK_ROWS, LOADERS, LazyChunks, ResidentSet
from .stream_cut import (SPHERE_PAGES_PER_SPLAT, VIEWER_FRAMES, choose_cut, plan_for,
                         tree_cache_need)
from .stream_frames import framing_scene
from .stream_gather import Cancelled

#: Seconds :meth:`StreamedScene.close` waits for a background gather to stop.
GATHER_JOIN_S = 10.0


def _same(a: tuple, b: tuple | None) -> bool:
    """Whether ``a`` and ``b`` are the same cut ``(rows, weights, ...)``."""
    return (b is not None and np.array_equal(a[0], b[0]) and (a[1] is None) == (b[1] is None)
            and (a[1] is None or np.array_equal(a[1], b[1])))


def weighted(scene: Scene, weights: np.ndarray | None) -> Scene:
    """``scene`` with each opacity ``o`` drawn as ``1 - (1 - o) ** w``."""
    if weights is None:
        return scene
    o = 1.0 - (1.0 - scene.opacities.astype(np.float64)) ** weights.astype(np.float64)
    return Scene.from_activated(scene.means, scene.quats, scene.scales, o, scene.sh, scene.kind)


class StreamedScene:
    """The ``.lod.ply`` at ``path`` for the viewer, under ``memory`` bytes (see the module doc);
    :attr:`framing` frames the views (a proxy, :func:`framing_scene`).  ``plan``: how the
    budget is shared (:func:`splatgl.lod.stream_cut.plan_for`, measured now): the chunks hold
    ``plan.cache`` bytes and a cut at most ``plan.cap`` nodes (:attr:`capped` says when the
    bound made one coarser than asked)."""

    def __init__(self, path, lod: LodSettings, memory: int, on_change=None,
                 chunk_rows: int = CHUNK_ROWS, threads: int = LOADERS, chunks=None,
                 plan: StreamPlan | None = None):
        self.lod, self.memory, self.on_change = lod, int(memory), on_change
        self.lazy = LazyLod(path)
        self.resident = None
        self.generation = 0
        self.complete = False
        self.capped: str | None = None
        self._last: tuple | None = None   # (rows, weights, scene) drawn last
        self._ready: tuple | None = None  # (rows, weights, scene, view) gathered in the background
        self._job: tuple | None = None    # (rows, weights, view) being gathered, the one wanted
        self._error: BaseException | None = None
        self._thread: threading.Thread | None = None
        self._jobs = threading.Lock()
        self._view: bytes | None = None   # the camera of the last draw
        try:
            self.framing = framing_scene(self.lazy)
            release_freed()
            chunks = chunks or LazyChunks(self.lazy, chunk_rows)
            need = tree_cache_need(chunks, self.lazy.offsets, threads)
            self.plan = plan or plan_for(self.lazy, self.memory, cache_need=need,
                                         frames=VIEWER_FRAMES)
            self.resident = ResidentSet(chunks, self.plan.cache,
                                        self.lazy.offsets, self.lazy.branching, threads,
                                        on_loaded=self._loaded)
            self.resident.load_pinned()   # the top levels: some ancestor is always there
        except BaseException:
            self.close()
            raise

    def _loaded(self) -> None:
        if self._job is not None:
            return   # a gather in flight: its end moves the generation on
        self._changed()

    def _changed(self) -> None:
        self.generation += 1
        if self.on_change is not None:
            self.on_change()

    def _camera(self, camera: Camera, settings: RenderSettings) -> Camera:
        return View.of(camera, settings, self.framing).camera   # the scene transform applied

    def _scene(self, rows: np.ndarray, weights: np.ndarray | None) -> Scene:
        for held in (self._last, self._ready):
            if _same((rows, weights), held):
                self._last = held
                return held[2]   # the same object: the renderer keeps its upload
        self._last = (rows, weights, self._build(rows, weights))
        return self._last[2]

    def _build(self, rows: np.ndarray, weights: np.ndarray | None, cancelled=None) -> Scene:
        scene = weighted(self.resident.gather(rows, cancelled), weights)
        scene.__dict__["anchor"] = np.asarray(self.lazy.anchor, np.float64)  # cached_property
        return scene

    def _gathered(self, rows: np.ndarray, weights: np.ndarray | None, view: bytes) -> Scene:
        """The cut that does not fit the cache: gathered in the background (see the module
        doc); its resident ancestors meanwhile (chunks not requested: the gather loads them)."""
        if self._error is not None:
            error, self._error = self._error, None
            raise error
        near = self.resident.resident_cut(rows, weights, request=False)
        self.complete = (near[2] or _same((rows, weights), self._last)
                         or _same((rows, weights), self._ready))
        with self._jobs:
            start = not self.complete and self._job is None
            if self.complete:
                self._job = None
            elif not _same((rows, weights), self._job):
                self._job = (rows, weights, view)   # one running for another cut abandons it
        if self.complete:
            return self._scene(rows, weights)
        if start:
            self._thread = threading.Thread(target=self._gather_jobs, daemon=True,
                                            name="splatgl-lod-gather")
            self._thread.start()
        return self._scene(*near[:2])

    def _gather_jobs(self) -> None:
        """The background gathers: the cut wanted, until none is (or the stream closes)."""
        stop = self.resident._stop
        while True:
            with self._jobs:
                job = self._job
                if job is None or stop.is_set():
                    self._job = None
                    return
            try:
                scene = self._build(*job[:2],
                                    cancelled=lambda: self._job is not job or stop.is_set())
            except Cancelled:
                continue
            except KeyboardInterrupt:
                return
            except BaseException as error:   # noqa: BLE001 - raised again by the next draw
                self._error = scene = error
            with self._jobs:
                if self._job is not job and self._job is not None:
                    continue   # another cut is wanted now
                if self._job is job and not isinstance(scene, BaseException):
                    self._ready = (job[0], job[1], scene, job[2])
                self._job = None
            self._changed()
            return

    def scene_for(self, camera: Camera, settings: RenderSettings,
                  lod: LodSettings | None = None) -> Scene:
        """The scene to draw now for ``camera`` (never waits; :attr:`complete` says whether it
        is the exact cut); ``lod``: another cut than the view's (the viewer's budgeted
        frames, :mod:`splatgl.interactive.stream_levels`)."""
        rows, weights = self._cut(camera, settings, lod or self.lod)
        view = camera.world_to_camera.tobytes()
        moved, self._view = view != self._view, view
        if self._ready is not None and self._ready[3] != view:
            self._ready = None   # gathered for another view: not held through a movement
        if lod is None and not self.resident.fits(rows):
            if not moved:
                return self._gathered(rows, weights, view)
            self._changed()   # a moving frame does not gather: at rest the next draw does
        with self._jobs:
            self._job = None   # another cut: a background gather is abandoned
        rows, weights, self.complete = self.resident.resident_cut(rows, weights)
        return self._scene(rows, weights)

    def exact_scene(self, camera: Camera, settings: RenderSettings) -> Scene:
        """The view's exact cut, waiting for its chunks."""
        return self._scene(*self._cut(camera, settings, self.lod))

    def _cut(self, camera: Camera, settings: RenderSettings, lod: LodSettings):
        """The view's ``(rows, weights)`` under the memory bound's cap."""
        choice = choose_cut(self.lazy, self._camera(camera, settings), lod, self.plan.cap)
        self.lazy.trim_spheres(SPHERE_PAGES_PER_SPLAT * 16 * self.plan.cap)
        self.capped = self.capped or choice.capped
        return choice.rows, choice.weights

    def summary(self) -> str:
        """Resident memory and chunks (the status panel)."""
        return (self.resident.stats.summary(self.plan.cache) + ("" if self.complete else ", refining")
                + (", capped by --memory" if self.capped else ""))

    def close(self) -> None:
        if self.resident is not None:
            self.resident.close()
        if self._thread is not None:   # it stops at its next chunk: then the file may close
            self._thread.join(GATHER_JOIN_S)
        self.lazy.close()
