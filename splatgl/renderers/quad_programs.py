"""The quad path's programs: which shaders, specialised by which ``#define`` switches.

One scene and its settings fix most switches (SH degree, extent, antialiasing, storage layout,
2DGS surfels, the compute pre-pass); the view adds its camera model's (:attr:`View.defines`),
and a frame adds what it asks for (the depth layer, early termination's batches, level-of-detail
opacity weights, a benchmark's fragment counters).  :class:`ProgramCache` compiles each variant
once.
"""

from __future__ import annotations

from dataclasses import dataclass

import moderngl

from ..cameras.view import View
from ..gl.scene_buffers import SceneBuffers
from ..gl.shaders import ProgramCache
from ..scene.splats import Scene, SplatKind
from ..scene.settings import Preprocess, QuadExtent
from .options import QuadOptions

#: Switches that only the draw programs read (the compute passes leave them out).
DRAW_ONLY = ("EARLY_STOP", "SURVIVORS", "COUNT_FRAGMENTS", "COUNT_RASTERISED", "ORDERED_PASS",
             "UNDER")


@dataclass(frozen=True)
class FrameSwitches:
    """What one frame asks of the programs.

    depth: write the depth layer (DEPTH_OUTPUT).  batched: early termination's batches
    (EARLY_STOP, and SURVIVORS after the pre-pass).  weights: per-slot opacity weights of a
    level-of-detail cut (OPACITY_WEIGHT).  extra: further switches (a benchmark probe's
    COUNT_FRAGMENTS).  normal: the normal layer's attachment (NORMAL_OUTPUT = its location;
    0: none).  ordered: the ordered pass's program (ORDERED_PASS).  ordered_rect: the frame
    has an ordered pass, so its quads keep the reference's radius (ORDERED_RECT).  under:
    test fragments against the geometry's depth (UNDER).
    """

    depth: bool = False
    batched: bool = False
    weights: bool = False
    extra: tuple[tuple[str, object], ...] = ()
    normal: int = 0
    ordered: bool = False
    ordered_rect: bool = False
    under: bool = False


#: The switches a frame turns on, from its :class:`FrameSwitches` field: 1 where the field is true
#: (NORMAL_OUTPUT: the normal layer's location; the pre-pass writes normals in either pass).
FRAME_SWITCHES = (("depth", "DEPTH_OUTPUT"), ("normal", "NORMAL_OUTPUT"), ("ordered", "ORDERED_PASS"),
                  ("ordered_rect", "ORDERED_RECT"), ("under", "UNDER"))


class QuadPrograms:
    """The quad path's programs for one scene and its options (see the module doc)."""

    def __init__(self, scene: Scene, options: QuadOptions, buffers: SceneBuffers,
                 programs: ProgramCache):
        self.scene, self.options, self.buffers, self.cache = scene, options, buffers, programs
        self.surfels = scene.kind is SplatKind.SURFEL_2D
        #: The compute pre-pass covers 3DGS; surfels always take their vertex stage.
        self.uses_prepass = options.preprocess is Preprocess.COMPUTE and not self.surfels

    def defines(self, view: View, frame: FrameSwitches) -> dict[str, object]:
        """Every switch of the draw programs for this scene, view and frame."""
        cap = self.options.sh_degree
        defines: dict[str, object] = {
            "SH_DEGREE": self.scene.sh_degree if cap is None else min(cap, self.scene.sh_degree),
            "SH_REST_COEFFS": self.buffers.sh_rest_coeffs,
        }
        if self.options.extent is QuadExtent.SQUARE:
            defines["EXTENT_SQUARE"] = 1
        elif self.options.extent is QuadExtent.FAST:
            defines["EXTENT_FAST"] = 1
        if self.options.antialias:
            defines["ANTIALIAS"] = 1
        defines.update(view.defines)
        defines.update((name, int(getattr(frame, field))) for field, name in FRAME_SWITCHES
                       if getattr(frame, field))
        defines.update(frame.extra)
        defines.update(self.buffers.defines())
        if frame.batched:
            defines["EARLY_STOP"] = 1
            if self.uses_prepass:
                defines["SURVIVORS"] = 1
        if frame.weights:
            defines["OPACITY_WEIGHT"] = 1
        return defines

    def compute_defines(self, view: View, frame: FrameSwitches) -> dict[str, object]:
        """:meth:`defines` without the draw-only switches."""
        return {k: v for k, v in self.defines(view, frame).items() if k not in DRAW_ONLY}

    def draw(self, view: View, frame: FrameSwitches) -> moderngl.Program:
        """The draw program: full per-corner math, or the light one after the pre-pass.

        2DGS surfels use shaders/surfel.vert + surfel.frag (ray-splat intersection); the
        extent and antialiasing settings are 3DGS-only and do not change them.
        """
        if self.surfels:
            return self.cache.program("surfel.vert", "surfel.frag", self.defines(view, frame))
        vertex = "quad_light.vert" if self.uses_prepass else "quad.vert"
        return self.cache.program(vertex, "quad.frag", self.defines(view, frame))

    def prepass(self, view: View, frame: FrameSwitches) -> moderngl.ComputeShader:
        """shaders/quad_prepass.comp for this view and frame."""
        return self.cache.compute("quad_prepass.comp", self.compute_defines(view, frame))

    def rect(self, view: View, name: str, frame: FrameSwitches) -> moderngl.ComputeShader:
        """``name`` (occlusion_cull.comp, coverage.comp) in the variant that reads this path's
        splat rectangles (shaders/lib/splat_rect.glsl): from the pre-pass's output, or a
        surfel's or a 3DGS splat's own setup."""
        defines = self.compute_defines(view, FrameSwitches(weights=frame.weights, extra=frame.extra))
        if self.uses_prepass:
            defines["PREPARED"] = 1
        elif self.surfels:
            defines["SURFEL"] = 1
        return self.cache.compute(name, defines)
