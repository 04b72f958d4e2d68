"""Offscreen float render targets and their readback."""

from __future__ import annotations

import moderngl
import numpy as np

from ..settings import Precision

_DTYPES = {Precision.RGBA32F: "f4", Precision.RGBA16F: "f2", Precision.RGBA8: "f1"}


class ColorTarget:
    """An RGBA framebuffer of the given precision; row 0 of the readback is framebuffer row 0."""

    def __init__(self, ctx: moderngl.Context, width: int, height: int, precision: Precision):
        self.size = (width, height)
        self.precision = precision
        self.texture = ctx.texture((width, height), 4, dtype=_DTYPES[precision])
        self.fbo = ctx.framebuffer(color_attachments=[self.texture])

    def read(self) -> np.ndarray:
        """(H, W, 4) float32 contents."""
        w, h = self.size
        dtype = _DTYPES[self.precision]
        raw = self.fbo.read(components=4, dtype=dtype)
        if dtype == "f1":
            return np.frombuffer(raw, np.uint8).reshape(h, w, 4).astype(np.float32) / 255.0
        return np.frombuffer(raw, np.float16 if dtype == "f2" else np.float32).reshape(h, w, 4).astype(np.float32)

    def release(self) -> None:
        self.fbo.release()
        self.texture.release()
