"""The limit row: the quad path's geometry drawn with trivial shaders (fill + per-primitive cost).

Each configuration's frame time reads as a ratio to this: what this machine's OpenGL can do at
best with the same quads, blending and target.
"""

from __future__ import annotations

import dataclasses
import time

import moderngl
import numpy as np

from ...cameras.view import View
from ...gl.shaders import ProgramCache
from ...output.layers import RenderOutput
from ...renderers.quad import QuadRenderer, QuadTimes, composite
from ...scene.splats import Scene
from ...gl.transfers import transfers
from ...scene.settings import Preprocess, RenderSettings, SortKey


class LimitRenderer:
    """Draws the quads of ``settings``' extent with shaders/limit.vert + limit.frag.

    Per frame the geometry is prepared by the quad path's cull, sort and compute pre-pass,
    untimed; ``last_times`` holds only the trivial draw and the readback.
    """

    def __init__(self, ctx: moderngl.Context, scene: Scene, settings: RenderSettings,
                 programs: ProgramCache | None = None):
        self.ctx = ctx
        self.scene = scene
        self.settings = settings
        # the CPU order: the trivial draw needs the count on the host (the device order keeps it
        # in its draw command), and the order does not change what a limit frame costs
        self.quad = QuadRenderer(ctx, scene, dataclasses.replace(
            settings, preprocess=Preprocess.COMPUTE,
            sort_key=SortKey.EXACT if settings.sort_key is SortKey.GPU else settings.sort_key),
            programs)
        self.program = self.quad.programs.cache.program("limit.vert", "limit.frag")
        self.vao = ctx.vertex_array(self.program, [])
        self.last_times: QuadTimes | None = None

    def render(self, view: View) -> RenderOutput:
        before = transfers(self.ctx).snapshot()
        count, _ = self.quad.prepare(view)   # cull, sort, upload, pre-pass: untimed
        target = self.quad.target(view)
        self.program["u_viewport"].value = (float(view.width), float(view.height))
        t0 = time.perf_counter()
        target.fbo.use()
        self.ctx.viewport = (0, 0, view.width, view.height)
        target.fbo.clear(0.0, 0.0, 0.0, 0.0)
        self.ctx.enable(moderngl.BLEND)
        self.ctx.blend_func = moderngl.ONE_MINUS_DST_ALPHA, moderngl.ONE
        if count:
            self.vao.render(moderngl.TRIANGLE_STRIP, vertices=4, instances=count)
        self.ctx.disable(moderngl.BLEND)
        self.ctx.finish()
        t1 = time.perf_counter()
        rgba = target.read()
        t2 = time.perf_counter()
        self.last_times = QuadTimes(0.0, 0.0, 0.0, 0.0, t1 - t0, t2 - t1, count,
                                    transfers=transfers(self.ctx).snapshot().since(before))
        return RenderOutput(composite(rgba, self.settings.background), np.zeros(rgba.shape[:2], np.float32))

    def release(self) -> None:
        self.vao.release()
        self.quad.release()
