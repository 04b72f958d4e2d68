"""Upscaling a draft frame to the window: Catmull-Rom bicubic, on the GPU and in NumPy.

A moving frame drawn at a fraction of the window's pixels is shown at full size through this
filter (shaders/upscale.frag).  Catmull-Rom (the cubic with B = 0, C = 1/2) interpolates: a
pixel of the draft keeps its value where it lands, edges stay sharper than bilinear's, and its
small negative lobes ring a little at hard edges; the ringing is clipped (alpha to [0, 1],
colour to at least 0).  It works on the premultiplied ``(C, A)`` target, so the background is
composited after the filter, as for a full-size frame.

:func:`upscale` is the float64 NumPy twin of the shader (the same sample positions, taps and
clipping); :class:`Upscaler` runs the shader into a texture of the window's size.
"""

from __future__ import annotations

import moderngl
import numpy as np

from ..gl.bindings import UPSCALE_UNIT
from ..gl.shaders import preprocess


def catmull_rom_weights(t: np.ndarray) -> np.ndarray:
    """(..., 4) weights of the taps at offsets -1, 0, 1, 2 for fractions ``t`` in [0, 1)."""
    t = np.asarray(t, np.float64)
    t2, t3 = t * t, t * t * t
    return 0.5 * np.stack([-t3 + 2 * t2 - t, 3 * t3 - 5 * t2 + 2, -3 * t3 + 4 * t2 + t, t3 - t2], -1)


def _axis(src: int, dst: int) -> tuple[np.ndarray, np.ndarray]:
    """(dst, 4) source indices (clamped to the edge) and weights for one axis."""
    u = (np.arange(dst, dtype=np.float64) + 0.5) * (src / dst) - 0.5
    base = np.floor(u)
    idx = np.clip(base[:, None].astype(np.int64) + np.arange(-1, 3), 0, src - 1)
    return idx, catmull_rom_weights(u - base)


def upscale(image: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    """``image`` ((h, w, C) premultiplied, row 0 = top) resampled to ``size`` = (W, H) by the
    filter of shaders/upscale.frag; float64, clipped like the shader (last channel = alpha)."""
    img = np.asarray(image, np.float64)
    h, w = img.shape[:2]
    width, height = size
    ix, wx = _axis(w, width)
    iy, wy = _axis(h, height)
    rows = np.einsum("yk,ykxc->yxc", wy, img[iy])           # (H, w, C)
    out = np.einsum("xk,yxkc->yxc", wx, rows[:, ix])         # (H, W, C)
    out[..., :-1] = np.maximum(out[..., :-1], 0.0)
    out[..., -1] = np.clip(out[..., -1], 0.0, 1.0)
    return out


class Upscaler:
    """Runs shaders/upscale.frag on ``ctx``: :meth:`run` fills a float texture of the target
    size (premultiplied, row 0 = top) from a smaller one, kept for the next frame of that size.
    It leaves its own framebuffer bound: the caller binds where it draws next."""

    def __init__(self, ctx: moderngl.Context):
        self.ctx = ctx
        self.program = ctx.program(vertex_shader=preprocess("fullscreen.vert").text,
                                   fragment_shader=preprocess("upscale.frag").text)
        self.vao = ctx.vertex_array(self.program, [])
        self.texture: moderngl.Texture | None = None
        self.fbo: moderngl.Framebuffer | None = None

    def run(self, source: moderngl.Texture, size: tuple[int, int]) -> moderngl.Texture:
        """``source`` upscaled to ``size`` (w, h); the returned texture is reused next call."""
        if self.texture is None or self.texture.size != tuple(size):
            self._release_target()
            self.texture = self.ctx.texture(tuple(size), 4, dtype="f4")
            self.fbo = self.ctx.framebuffer(color_attachments=[self.texture])
        source.use(UPSCALE_UNIT)
        self.program["u_ratio"].value = (source.size[0] / size[0], source.size[1] / size[1])
        self.fbo.use()
        self.ctx.viewport = (0, 0, *size)
        self.ctx.disable(moderngl.BLEND | moderngl.DEPTH_TEST | moderngl.CULL_FACE)
        self.vao.render(moderngl.TRIANGLES, vertices=3)
        return self.texture

    def read(self) -> np.ndarray:
        """(H, W, 4) float32 of the last :meth:`run`."""
        w, h = self.texture.size
        return np.frombuffer(self.fbo.read(components=4, dtype="f4"), np.float32).reshape(h, w, 4).copy()

    def _release_target(self) -> None:
        if self.fbo is not None:
            self.ctx.detect_framebuffer(0).use()
            self.fbo.release()
            self.texture.release()
            self.fbo = self.texture = None

    def release(self) -> None:
        self._release_target()
        self.vao.release()
        self.program.release()
