"""Budgeted frames over a level of detail streamed from disk (``splatgl view --memory``, issue 41
items 3 and 6): the viewer's frame-time budget (:class:`~.session.Session`) with each level drawn
from what is resident.

:class:`StreamedLevels` is the session's :class:`~.draft.LevelRenderer` for a
:class:`splatgl.lod.stream_view.StreamedScene`: a level with a splat budget draws the budget's
cut (the in-memory drafts' cut, :data:`~.draft.CUT_THRESHOLD_PX` under the budget) and a
full-detail level the view's own cut, each as far as its chunks are resident (their nearest
resident ancestors stand in for the rest, whose chunks are requested); the render scale and the
SH cap apply as to any level.  :attr:`StreamedLevels.complete` says whether the last draw had
every chunk it needed, and :attr:`StreamedLevels.generation` counts the chunks arrived: the
session draws the exact level again as chunks arrive until a draw is complete (then the frame is
exact), :meth:`~.session.Session.frame`.

:func:`streamed_session` is the one way to build that session: the viewer's pacer and the
streamed flight of ``bench --scale --lod`` (:mod:`splatgl.measure.bench.flight`) both call it.
"""

from __future__ import annotations

import dataclasses

from ..api import Renderer
from ..cameras.camera import Camera
from ..errors import SplatglError
from ..gl.context import make_current
from ..lod.selection import LodSettings
from ..renderers import registry
from ..renderers.early_stop import MAX_BATCH, BatchHook
from ..renderers.quad import QuadRenderer
from ..scene.settings import RendererKind, RenderSettings
from .budget import Level
from .draft import CUT_THRESHOLD_PX, DRAFT_TRIANGLES, DraftFrame, LevelRenderer
from .session import Session, camera_key


class StreamedLevels(LevelRenderer):
    """Draws a streamed level of detail (``stream``, a
    :class:`~splatgl.lod.stream_view.StreamedScene`) at any level (see the module doc).  Each
    kind of level (full detail or a cut, and its SH cap) keeps one quad renderer over the
    scene it drew last; a new scene releases the old one's upload, and a cut drawn for a new
    view (a moving frame) releases full detail drawn for another view (at 5M splats its cut
    and upload, 0.6 GB, were held through the whole movement)."""

    def __init__(self, renderer: Renderer, stream, settings: RenderSettings,
                 triangles: bool = DRAFT_TRIANGLES):
        super().__init__(renderer, stream.framing, settings, None, triangles)
        self.stream = stream
        self.complete = True
        self.drawn_generation = stream.generation
        self._camera: Camera | None = None
        self._paths: dict[tuple, tuple[object, QuadRenderer, tuple]] = {}   # scene, quad, view

    @property
    def has_lod(self) -> bool:
        return True

    @property
    def generation(self) -> int:
        """Chunks arrived so far."""
        return self.stream.generation

    def draw(self, camera: Camera, level: Level, on_batch: BatchHook | None = None,
             max_batch: int = MAX_BATCH) -> DraftFrame:
        self._camera = camera   # the cut is the view's (_quad has no camera)
        return super().draw(camera, level, on_batch, max_batch)

    def _quad(self, level: Level) -> QuadRenderer:
        stream = self.stream
        lod = None if level.budget is None else LodSettings(CUT_THRESHOLD_PX, level.budget)
        view = camera_key(self._camera)
        if level.budget is not None:   # a cut for a new view: another view's full detail goes
            self._drop(lambda key, drawn_for: key[0] and drawn_for != view)
        else:   # full detail for a new view: the last view's goes before the new cut is gathered
            self._drop(lambda key, drawn_for: key == (True, level.sh_degree) and drawn_for != view)
        self.drawn_generation = stream.generation   # before the cut: one after it draws again
        scene = stream.scene_for(self._camera, self.settings, lod)
        self.complete = bool(stream.complete)
        settings = (self.settings if level.sh_degree is None else
                    dataclasses.replace(self.settings, sh_degree=level.sh_degree))
        key = (level.budget is None, level.sh_degree)
        held = self._paths.get(key)
        if held is not None and held[0] is scene:
            self._paths[key] = (scene, held[1], view)
            return held[1]
        self._drop(lambda k, drawn_for: k == key)
        make_current(self.renderer.ctx)
        quad = registry.make(RendererKind.QUAD, scene, settings, self.renderer.ctx,
                             self.renderer.programs)
        self._paths[key] = (scene, quad, view)
        return quad

    def _drop(self, which) -> None:
        """Release the renderers (their scene's upload) ``which(key, view drawn for)`` names."""
        for key in [k for k, (_, _, drawn_for) in self._paths.items() if which(k, drawn_for)]:
            self._paths.pop(key)[1].release()

    def draw_cpu(self, camera: Camera, on_batch: BatchHook | None = None) -> DraftFrame:
        raise SplatglError("--renderer cpu and --memory (streaming a level of detail) cannot be "
                           "combined yet: the exact frame at rest is the quad path's")

    def release(self) -> None:
        self._drop(lambda key, drawn_for: True)
        super().release()


def streamed_session(renderer: Renderer, stream, settings: RenderSettings, budget: float) -> Session:
    """The viewer's session over ``stream`` (a :class:`~splatgl.lod.stream_view.StreamedScene`)
    with ``budget`` seconds a moving frame: the quad path's exact frame at rest."""
    return Session(renderer, stream.framing, settings, budget,
                   levels=StreamedLevels(renderer, stream, settings))
