"""Offscreen float render targets and their readback."""

from __future__ import annotations

import moderngl
import numpy as np

from ..model.settings import Precision

_DTYPES = {Precision.RGBA32F: "f4", Precision.RGBA16F: "f2", Precision.RGBA8: "f1"}


class ColorTarget:
    """An RGBA framebuffer of the given precision; row 0 of the readback is framebuffer row 0.

    With ``depth``, a second RGBA32F attachment receives the depth layer (always float32:
    depth values are not in [0, 1] and need the range).  With ``stop_mask``, a depth buffer
    (early termination's per-pixel stop mask, splatgl/renderers/early_stop.py) is attached to ``fbo``, and
    ``mask_fbo`` holds it alone, so the mark pass can sample ``texture`` while writing it.
    """

    def __init__(self, ctx: moderngl.Context, width: int, height: int, precision: Precision,
                 depth: bool = False, stop_mask: bool = False):
        self.size = (width, height)
        self.precision = precision
        self.texture = ctx.texture((width, height), 4, dtype=_DTYPES[precision])
        self.depth_texture = ctx.texture((width, height), 4, dtype="f4") if depth else None
        attachments = [self.texture] + ([self.depth_texture] if depth else [])
        self.stop_depth = ctx.depth_renderbuffer((width, height)) if stop_mask else None
        self.fbo = ctx.framebuffer(color_attachments=attachments, depth_attachment=self.stop_depth)
        self.mask_fbo = ctx.framebuffer(depth_attachment=self.stop_depth) if stop_mask else None
        self.has_depth = depth
        self.has_stop_mask = stop_mask

    def read_depth(self) -> np.ndarray:
        """(H, W) float32 accumulated depth (red channel of the depth attachment)."""
        w, h = self.size
        raw = self.fbo.read(components=4, dtype="f4", attachment=1)
        return np.frombuffer(raw, np.float32).reshape(h, w, 4)[..., 0].copy()

    def read(self) -> np.ndarray:
        """(H, W, 4) float32 contents."""
        w, h = self.size
        dtype = _DTYPES[self.precision]
        raw = self.fbo.read(components=4, dtype=dtype)
        if dtype == "f1":
            return np.frombuffer(raw, np.uint8).reshape(h, w, 4).astype(np.float32) / 255.0
        return np.frombuffer(raw, np.float16 if dtype == "f2" else np.float32).reshape(h, w, 4).astype(np.float32)

    def release(self) -> None:
        # Bind the default framebuffer first: moderngl re-binds the last used framebuffer after
        # creating the next one, and binding a deleted name is GL_INVALID_OPERATION.
        self.fbo.ctx.detect_framebuffer(0).use()
        self.fbo.release()
        if self.mask_fbo is not None:
            self.mask_fbo.release()
            self.stop_depth.release()
        self.texture.release()
        if self.depth_texture is not None:
            self.depth_texture.release()
