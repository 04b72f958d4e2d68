"""Upscaling a draft frame to the window: Catmull-Rom bicubic, on the GPU and in NumPy.

A moving frame drawn at a fraction of the window's pixels is shown at full size through this
filter (shaders/upscale.frag).  Catmull-Rom (the cubic with B = 0, C = 1/2) interpolates: a
pixel of the draft keeps its value where it lands, edges stay sharper than bilinear's, and its
small negative lobes ring a little at hard edges; the ringing is clipped (alpha to [0, 1],
colour to at least 0).  It works on the premultiplied ``(C, A)`` target, so the background is
composited after the filter, as for a full-size frame.

:class:`Upscaler` runs the shader into a texture of the window's size; its float64 NumPy twin
(the same sample positions, taps and clipping) is :func:`splatgl.splatmath.upscale.upscale`.
"""

from __future__ import annotations

import moderngl
import numpy as np

from ..gl.bindings import UPSCALE_UNIT
from ..gl.shaders import preprocess


class Upscaler:
    """Runs shaders/upscale.frag on ``ctx``: :meth:`run` fills a float texture of the target
    size (premultiplied, row 0 = top) from a smaller one in two passes (along x into a
    (target width, source height) texture, then along y), both kept for the next frame of
    those sizes.  It leaves its own framebuffer bound: the caller binds where it draws next."""

    def __init__(self, ctx: moderngl.Context):
        self.ctx = ctx
        self.program = ctx.program(vertex_shader=preprocess("fullscreen.vert").text,
                                   fragment_shader=preprocess("upscale.frag").text)
        self.vao = ctx.vertex_array(self.program, [])
        self._targets: dict[str, tuple[moderngl.Texture, moderngl.Framebuffer]] = {}
        self.texture: moderngl.Texture | None = None

    def _target(self, role: str, size: tuple[int, int]) -> tuple[moderngl.Texture, moderngl.Framebuffer]:
        kept = self._targets.get(role)
        if kept is None or kept[0].size != tuple(size):
            if kept is not None:
                self._release(role)
            texture = self.ctx.texture(tuple(size), 4, dtype="f4")
            kept = self._targets[role] = (texture, self.ctx.framebuffer(color_attachments=[texture]))
        return kept

    def _pass(self, source: moderngl.Texture, fbo: moderngl.Framebuffer, axis: int, ratio: float) -> None:
        source.use(UPSCALE_UNIT)
        self.program["u_axis"].value = axis
        self.program["u_ratio"].value = ratio
        fbo.use()
        self.ctx.viewport = (0, 0, *fbo.size)
        self.vao.render(moderngl.TRIANGLES, vertices=3)

    def run(self, source: moderngl.Texture, size: tuple[int, int]) -> moderngl.Texture:
        """``source`` upscaled to ``size`` (w, h); the returned texture is reused next call."""
        (sw, sh), (w, h) = source.size, size
        self.ctx.disable(moderngl.BLEND | moderngl.DEPTH_TEST | moderngl.CULL_FACE)
        rows, rows_fbo = self._target("rows", (w, sh))
        self._pass(source, rows_fbo, 0, sw / w)
        out, out_fbo = self._target("out", (w, h))
        self._pass(rows, out_fbo, 1, sh / h)
        self.texture = out
        return out

    def read(self) -> np.ndarray:
        """(H, W, 4) float32 of the last :meth:`run`."""
        texture, fbo = self._targets["out"]
        w, h = texture.size
        return np.frombuffer(fbo.read(components=4, dtype="f4"), np.float32).reshape(h, w, 4).copy()

    def _release(self, role: str) -> None:
        texture, fbo = self._targets.pop(role)
        self.ctx.detect_framebuffer(0).use()
        fbo.release()
        texture.release()

    def release(self) -> None:
        for role in list(self._targets):
            self._release(role)
        self.vao.release()
        self.program.release()
