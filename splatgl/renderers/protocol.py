"""The renderer interface: what every renderer of :mod:`splatgl.renderers.registry` is.

Every renderer follows :class:`FrameRenderer`: made once per (scene, options), it renders a
per-frame :class:`~splatgl.cameras.view.View`, keeps the last frame's stage times
(:class:`StageTimes`) and releases what it holds.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Protocol, runtime_checkable

from ..scene.splats import Scene
from ..scene.settings import RendererKind
from ..output.layers import BASE, Layer, RenderOutput

if TYPE_CHECKING:
    from ..cameras.view import View
    from ..output.under import UnderLayer
    from .options import DrawOptions


@runtime_checkable
class StageTimes(Protocol):
    """A renderer's stage times of one frame (a frozen dataclass of seconds and counts)."""

    @property
    def total(self) -> float: ...
    @property
    def ordering(self) -> float:
        """Seconds of the work before blending (cull, project, sort)."""
    @property
    def drawing(self) -> float:
        """Seconds of drawing: uploading, binning and blending the splats."""
    def summary(self, count: int) -> str:
        """The viewer's line on the splats of a scene of ``count`` splats ("splats 10 drawn / 12")."""


@runtime_checkable
class FrameRenderer(Protocol):
    """A renderer of one scene under its own options, reused across views."""

    kind: RendererKind
    scene: Scene
    #: Its own part of the settings (:mod:`splatgl.renderers.options`; a View is made with it).
    options: "DrawOptions"
    #: The last frame's :class:`StageTimes` (None before the first).
    last_times: StageTimes | None

    def supports(self, view: "View", layers: frozenset[Layer] = BASE,
                 under: "UnderLayer | None" = None) -> str | None:
        """Why this renderer cannot draw the request (one line), or None
        (:func:`splatgl.renderers.registry.refusal`)."""
    def render(self, view: "View", layers: frozenset[Layer] = BASE,
               under: "UnderLayer | None" = None) -> RenderOutput:
        """The ``layers`` of ``view``: RGB = C + (1 - A) background, alpha = A, row 0 on top."""
    def release(self) -> None:
        """Free what the renderer holds (GPU objects); it is not used afterwards."""
