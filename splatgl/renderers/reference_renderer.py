"""The NumPy per-tile reference (:func:`splatgl.reference.render_reference`) behind the renderer
interface (:class:`~splatgl.renderers.registry.FrameRenderer`): float32 math, no OpenGL."""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass

from ..cameras.view import View
from ..gl.context import NO_GL_RENDERER
from ..scene.splats import Scene
from ..scene.settings import RendererKind, RenderSettings
from ..output.layers import BASE, Layer, RenderOutput
from ..output.under import UnderLayer
from ..reference import render_reference
from .options import ReferenceRendererOptions
from .registry import Registered, check


@dataclass(frozen=True)
class ReferenceTimes:
    """Seconds of the reference's last frame (its stages are not timed apart)."""

    total: float

    @property
    def ordering(self) -> float:
        return 0.0

    @property
    def drawing(self) -> float:
        return self.total

    def summary(self, count: int) -> str:
        return f"splats {count:,}"


def describe() -> str:
    """What ``--timings`` prints as the GL renderer of a reference frame."""
    return NO_GL_RENDERER


class ReferenceRenderer(Registered):
    """Renders one scene with the NumPy reference.  ``progress`` (set per frame by
    :class:`splatgl.Renderer`) hears of the tiles rasterized."""

    kind = RendererKind.REFERENCE

    def __init__(self, scene: Scene, options: ReferenceRendererOptions | RenderSettings):
        options = self.own(options)
        check(self.kind, scene=scene)
        self.scene = scene
        # the View carries the scene transform folded into its camera
        self._plain = dataclasses.replace(options, transform=None).as_settings()
        self.last_times: ReferenceTimes | None = None
        self.progress = None

    def render(self, view: View, layers: frozenset[Layer] = BASE,
               under: UnderLayer | None = None) -> RenderOutput:
        """The ``layers`` of ``view`` (colour, alpha and depth always), composited into
        ``under`` if given."""
        layers = frozenset(layers)
        self.check(view, layers, under)
        t0 = time.perf_counter()
        ref = render_reference(self.scene, view.camera, self._plain,
                               compat=self.options.reference, progress=self.progress,
                               layers=layers, under=under)
        self.last_times = ReferenceTimes(time.perf_counter() - t0)
        return ref.output(layers)

    def release(self) -> None:
        """Nothing to free (NumPy arrays only)."""
