"""Putting images on the window: one fullscreen-triangle program (splatgl/viewer/shaders/present.*).

The splats are never drawn into the window's framebuffer (it may lack alpha, DESIGN.md
section 4); they are drawn into the quad path's own float target, or come back as NumPy images
(tile path, depth and difference views), and this module samples them onto the window.
"""

from __future__ import annotations

import enum
from pathlib import Path

import moderngl
import numpy as np

from ..gl.bindings import PRESENT_UNIT
from ..gl.shaders import preprocess

_SHADERS = Path(__file__).resolve().parent / "shaders"


class Mode(enum.IntEnum):
    """How :class:`Presenter` treats a texture (``MODE_*`` defines of splatgl/viewer/shaders/present.frag)."""

    PREMULTIPLIED = 0  # raw quad target (C, A): composite the background
    OPAQUE = 1         # already composited RGB
    OVERLAY = 2        # straight-alpha RGBA, alpha-blended over what is there


def fit_viewport(image_size: tuple[int, int], window_size: tuple[int, int]) -> tuple[int, int, int, int]:
    """(x, y, w, h) GL viewport showing an image of ``image_size`` (w, h) as large as fits in
    ``window_size``, centred, keeping its aspect ratio (exact when the sizes are equal)."""
    iw, ih = image_size
    ww, wh = window_size
    if (iw, ih) == (ww, wh):
        return 0, 0, ww, wh
    s = min(ww / iw, wh / ih)
    w, h = max(1, round(iw * s)), max(1, round(ih * s))
    return (ww - w) // 2, (wh - h) // 2, w, h


class Presenter:
    """Draws textures onto the current framebuffer; reuse one upload texture per role."""

    def __init__(self, ctx: moderngl.Context):
        self.ctx = ctx
        defines = {f"MODE_{mode.name}": str(int(mode)) for mode in Mode}
        self.program = ctx.program(
            vertex_shader=preprocess("present.vert", defines, root=_SHADERS).text,
            fragment_shader=preprocess("present.frag", defines, root=_SHADERS).text)
        self.vao = ctx.vertex_array(self.program, [])
        self._uploads: dict[str, moderngl.Texture] = {}

    def upload(self, role: str, image: np.ndarray) -> moderngl.Texture:
        """An RGBA32F texture holding ``image`` ((H, W, 4) float, row 0 = top), kept per ``role``."""
        h, w = image.shape[:2]
        tex = self._uploads.get(role)
        if tex is None or tex.size != (w, h):
            if tex is not None:
                tex.release()
            tex = self.ctx.texture((w, h), 4, dtype="f4")
            self._uploads[role] = tex
        tex.write(np.ascontiguousarray(image, np.float32))
        return tex

    def draw(self, texture: moderngl.Texture, mode: Mode, viewport: tuple[int, int, int, int],
             background=(0.0, 0.0, 0.0)) -> None:
        """Sample ``texture`` over ``viewport`` of the bound framebuffer."""
        # Same size: one texel per pixel, exactly.  Scaled (depth/difference pictures with their
        # scale bar): linear filtering, which every texture format here supports.
        same = texture.size == tuple(viewport[2:])
        texture.filter = (moderngl.NEAREST, moderngl.NEAREST) if same else (moderngl.LINEAR, moderngl.LINEAR)
        texture.use(PRESENT_UNIT)
        self.program["u_mode"].value = int(mode)
        if "u_background" in self.program:
            self.program["u_background"].value = tuple(float(v) for v in background)
        self.ctx.viewport = viewport
        self.ctx.disable(moderngl.DEPTH_TEST | moderngl.CULL_FACE)
        if mode is Mode.OVERLAY:
            self.ctx.enable(moderngl.BLEND)
            self.ctx.blend_func = moderngl.SRC_ALPHA, moderngl.ONE_MINUS_SRC_ALPHA
            self.ctx.blend_equation = moderngl.FUNC_ADD
        else:
            self.ctx.disable(moderngl.BLEND)
        self.vao.render(moderngl.TRIANGLES, vertices=3)
        self.ctx.disable(moderngl.BLEND)

    def release(self) -> None:
        for tex in self._uploads.values():
            tex.release()
        self._uploads.clear()
        self.vao.release()
        self.program.release()
