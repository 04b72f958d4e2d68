"""The viewer's scene of a level of detail streamed from disk (``splatgl view --memory``, issue 41
item 3): what is resident now, refined as chunks arrive.

:meth:`StreamedScene.scene_for` never waits: it chooses the view's cut (as a path frame does,
:func:`splatgl.lod.stream_frames.choose_cut`), draws the nodes whose chunks are resident and,
for the others, their nearest resident ancestors
(:meth:`splatgl.lod.stream.ResidentSet.resident_cut`), and requests the missing chunks;
``on_change`` (the viewer wakes its loop) is called as each arrives and :attr:`generation`
counts them, so the viewer draws again and the image refines until :attr:`complete`: then it is
the view's exact cut.  :meth:`exact_scene` waits for every chunk (screenshots).  A cut's opacity
weights are applied to the nodes' opacities (:func:`splatgl.lod.selection.blended_scene`'s rule),
so any renderer draws the scene.
"""

from __future__ import annotations

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
        self.generation += 1
        if self.on_change is not None:
            self.on_change()

    def _camera(self, camera: Camera, settings: RenderSettings) -> Camera:
        return View.of(camera, settings, self.framing).camera   # the scene transform applied

    def _scene(self, rows: np.ndarray, weights: np.ndarray | None) -> Scene:
        last = self._last
        if (last is not None and np.array_equal(last[0], rows)
                and (last[1] is None) == (weights is None)
                and (weights is None or np.array_equal(last[1], weights))):
            return last[2]   # the same object: the renderer keeps its upload
        scene = weighted(self.resident.gather(rows), weights)
        scene.__dict__["anchor"] = np.asarray(self.lazy.anchor, np.float64)  # cached_property
        self._last = (rows, weights, scene)
        return scene

    def scene_for(self, camera: Camera, settings: RenderSettings,
                  lod: LodSettings | None = None) -> Scene:
        """The scene to draw now for ``camera`` (never waits; :attr:`complete` says whether it
        is the exact cut); ``lod``: another cut than the view's (the viewer's budgeted
        frames, :mod:`splatgl.interactive.stream_levels`)."""
        rows, weights = self._cut(camera, settings, lod or self.lod)
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
        self.lazy.close()
