"""The viewer's scene of a Streamed SOG or LCC streamed from disk (``splatgl view --memory``,
issue 41 items 3 and 4): what is resident now, refined as chunks arrive; the interface of
:class:`splatgl.lod.stream_view.StreamedScene`.

The coarsest level of every chunk is loaded at open and never evicted (pinned).
:meth:`ChunkedScene.scene_for` never waits: it chooses the view's level per chunk
(:func:`splatgl.lod.level_cut.choose_levels`), draws each chunk at that level where it is
resident and otherwise at its nearest resident level (a coarser one first, the pinned coarsest at
worst), and requests the missing ones; ``on_change`` is called as each arrives and
:attr:`generation` counts them, so the viewer draws again until :attr:`complete`: then the image
is the view's exact choice.  :meth:`exact_scene` waits for every chunk (screenshots).
"""

from __future__ import annotations

import numpy as np

from ..cameras.camera import Camera
from ..scene.settings import RenderSettings
from ..scene.splats import Scene
from .budget import StreamPlan
from .level_cut import NOT_DRAWN
from .selection import LodSettings
from .stream import LOADERS
from .stream_levels import ChunkedStream


class ChunkedScene:
    """The Streamed SOG or LCC at ``path`` for the viewer, under ``memory`` bytes (see the
    module doc); ``level``: every chunk at that level (``--lod-level``) instead of the choice by
    screen error; :attr:`framing` frames the views; ``plan``: how ``memory`` is shared
    (:class:`~splatgl.lod.stream_levels.ChunkedStream`)."""

    def __init__(self, path, lod: LodSettings, memory: int, on_change=None,
                 level: int | None = None, threads: int = LOADERS, plan: StreamPlan | None = None):
        self.lod, self.memory, self.on_change = lod, int(memory), on_change
        self.generation = 0
        self.complete = False
        self._last: tuple | None = None   # (ids, scene) drawn last
        self.stream = ChunkedStream(path, lod, memory, level, threads, pinned=True,
                                    on_loaded=self._loaded, plan=plan)
        self.framing, self.resident = self.stream.framing, self.stream.resident
        self.levels = self.stream.structure.levels

    def _loaded(self) -> None:
        self.generation += 1
        if self.on_change is not None:
            self.on_change()

    def _scene(self, ids: list[int]) -> Scene:
        if self._last is not None and self._last[0] == ids:
            return self._last[1]   # the same object: the renderer keeps its upload
        scene = self.stream.scene_of(ids)
        self._last = (ids, scene)
        return scene

    def scene_for(self, camera: Camera, settings: RenderSettings,
                  lod: LodSettings | None = None) -> Scene:
        """The scene to draw now for ``camera`` (never waits; :attr:`complete` says whether it
        is the exact choice); ``lod``: another cut than the view's (the viewer's budgets)."""
        stream = self.stream
        levels = stream.choose(stream.view_camera(camera, settings), lod)
        want = stream.ids(levels)
        held = self.resident.held
        missing = [i for i in want if held(i) is None]
        if missing:
            self.resident.request(missing[::-1], keep=frozenset(set(want) - set(missing)))
        self.complete = not missing
        if self.complete:
            return self._scene(want)
        drawn = []
        for c in np.flatnonzero(levels != NOT_DRAWN).tolist():
            stand_in = self._resident_level(c, int(levels[c]))
            if stand_in is not None:
                drawn.append(stand_in)
        return self._scene(drawn)

    def _resident_level(self, chunk: int, level: int) -> int | None:
        """The resident-set chunk drawing ``chunk`` now: ``level``'s where resident, else the
        nearest resident coarser level, else the nearest finer one."""
        key = self.stream.chunks.key
        order = [level, *range(level + 1, self.levels), *range(level - 1, -1, -1)]
        for lv in order:
            i = key.get((chunk, lv))
            if i is not None and self.resident.held(i) is not None:
                return i
        return None

    def exact_scene(self, camera: Camera, settings: RenderSettings) -> Scene:
        """The view's exact choice, waiting for its chunks."""
        stream = self.stream
        return self._scene(stream.ids(stream.choose(stream.view_camera(camera, settings))))

    @property
    def capped(self) -> str | None:
        return self.stream.capped

    def summary(self) -> str:
        """Resident memory and chunks (the status panel)."""
        return self.stream.summary() + ("" if self.complete else ", refining")

    def close(self) -> None:
        self.stream.close()
