"""Offscreen float render targets and their readback."""

from __future__ import annotations

import moderngl
import numpy as np

from ..errors import SplatglError
from ..scene.settings import Precision
from .transfers import transfers

_DTYPES = {Precision.RGBA32F: "f4", Precision.RGBA16F: "f2", Precision.RGBA8: "f1"}


def _framebuffer(ctx: moderngl.Context, size: tuple[int, int], parts: list, **attachments):
    """``ctx.framebuffer(**attachments)``; a framebuffer the driver leaves incomplete (an
    attachment it would not allocate: llvmpipe refuses textures over about 1.5 GiB) is a
    one-line :class:`SplatglError` naming the image size, and ``parts`` are released."""
    try:
        return ctx.framebuffer(**attachments)
    except moderngl.Error as exc:
        error = ctx.error  # the allocation's GL_OUT_OF_MEMORY, cleared for the next check
        for part in parts:
            if part is not None:
                part.release()
        reason = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise SplatglError(
            f"image {size[0]}x{size[1]}: this OpenGL driver ({ctx.info.get('GL_RENDERER', '?')}) "
            f"could not allocate its render targets ({reason}, {error}); render a smaller "
            "image") from None


class ColorTarget:
    """An RGBA framebuffer of the given precision; row 0 of the readback is framebuffer row 0.

    With ``depth``, a second RGBA32F attachment receives the depth layer (always float32:
    depth values are not in [0, 1] and need the range); with ``normal``, a further RGBA32F
    attachment the normal layer (at :attr:`normal_location`: 2 after a depth attachment, else 1).  With ``stop_mask``, a depth buffer
    (early termination's per-pixel stop mask, splatgl/renderers/early_stop.py) is attached to ``fbo``, and
    ``mask_fbo`` holds it alone, so the mark pass can sample ``texture`` while writing it.
    """

    def __init__(self, ctx: moderngl.Context, width: int, height: int, precision: Precision,
                 depth: bool = False, stop_mask: bool = False, normal: bool = False):
        self.size = (width, height)
        self.precision = precision
        self.texture = ctx.texture((width, height), 4, dtype=_DTYPES[precision])
        self.depth_texture = ctx.texture((width, height), 4, dtype="f4") if depth else None
        self.normal_texture = ctx.texture((width, height), 4, dtype="f4") if normal else None
        attachments = [self.texture] + ([self.depth_texture] if depth else [])
        #: The attachment (and fragment output location) of the normal layer (0: none).
        self.normal_location = len(attachments) if normal else 0
        attachments += [self.normal_texture] if normal else []
        self.stop_depth = ctx.depth_renderbuffer((width, height)) if stop_mask else None
        self.fbo = _framebuffer(ctx, self.size, attachments + [self.stop_depth],
                                color_attachments=attachments, depth_attachment=self.stop_depth)
        self.mask_fbo = ctx.framebuffer(depth_attachment=self.stop_depth) if stop_mask else None
        self.has_depth = depth
        self.has_normal = normal
        self.has_stop_mask = stop_mask

    def read_depth(self) -> np.ndarray:
        """(H, W) float32 accumulated depth (red channel of the depth attachment)."""
        w, h = self.size
        raw = self.fbo.read(components=4, dtype="f4", attachment=1)
        transfers(self.fbo.ctx).read(len(raw))
        return np.frombuffer(raw, np.float32).reshape(h, w, 4)[..., 0].copy()

    def read_normal(self) -> np.ndarray:
        """(H, W, 3) float32 accumulated normal (rgb of the normal attachment)."""
        w, h = self.size
        raw = self.fbo.read(components=4, dtype="f4", attachment=self.normal_location)
        transfers(self.fbo.ctx).read(len(raw))
        return np.frombuffer(raw, np.float32).reshape(h, w, 4)[..., :3].copy()

    def read(self) -> np.ndarray:
        """(H, W, 4) float32 contents."""
        w, h = self.size
        dtype = _DTYPES[self.precision]
        raw = self.fbo.read(components=4, dtype=dtype)
        transfers(self.fbo.ctx).read(len(raw))
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
        for texture in (self.depth_texture, self.normal_texture):
            if texture is not None:
                texture.release()


class OrderedTarget:
    """The quad path's ordered pass targets (shaders/lib/ordered_layers.glsl): ``state``
    RGBA32F (T, median z, top weight, 0) and ``ids`` RGBA32UI (count, top index + 1, stopped,
    0), read and written by the fragment stage itself (framebuffer fetch)."""

    def __init__(self, ctx: moderngl.Context, width: int, height: int):
        self.size = (width, height)
        self.state = ctx.texture((width, height), 4, dtype="f4")
        self.ids = ctx.texture((width, height), 4, dtype="u4")
        self.fbo = _framebuffer(ctx, self.size, [self.state, self.ids],
                                color_attachments=[self.state, self.ids])
        self.state_fbo = ctx.framebuffer(color_attachments=[self.state])
        self._zeros = bytes(width * height * 16)

    def clear(self) -> None:
        """T = 1 and everything else 0 (an integer attachment cannot be cleared by glClear)."""
        self.state_fbo.clear(1.0, 0.0, 0.0, 0.0)
        transfers(self.ids.ctx).write(self.ids, self._zeros)

    def read(self) -> tuple[np.ndarray, np.ndarray]:
        """(H, W, 4) float32 state and (H, W, 4) uint32 ids."""
        w, h = self.size
        f = np.frombuffer(self.fbo.read(components=4, dtype="f4", attachment=0), np.float32)
        u = np.frombuffer(self.fbo.read(components=4, dtype="u4", attachment=1), np.uint32)
        transfers(self.fbo.ctx).read(f.nbytes + u.nbytes)
        return f.reshape(h, w, 4).copy(), u.reshape(h, w, 4).copy()

    def release(self) -> None:
        self.fbo.ctx.detect_framebuffer(0).use()
        self.fbo.release()
        self.state_fbo.release()
        self.state.release()
        self.ids.release()
