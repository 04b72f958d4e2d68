"""Image output through OpenImageIO: PNG and TIFF (8 or 16 bit, RGB), EXR (float RGBA)."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import OpenImageIO as oiio

from .errors import SplatglError

_INTEGER_FORMATS = {".png", ".tif", ".tiff"}
_FLOAT_FORMATS = {".exr"}


def write_image(path: str | Path, rgba: np.ndarray, bit_depth: int = 8,
                depth: np.ndarray | None = None) -> None:
    """Write an (H, W, 4) float32 image (row 0 at the top), atomically.

    PNG/TIFF get RGB (the background already composited), clipped to [0, 1] and quantised once
    to ``bit_depth`` (8 or 16).  EXR gets float32 R, G, B, A (A = accumulated alpha) and, when
    ``depth`` (H, W) is given, a Z channel (the expected depth, 0 where nothing was drawn).
    """
    path = Path(path)
    ext = path.suffix.lower()
    if ext not in _INTEGER_FORMATS | _FLOAT_FORMATS:
        raise SplatglError(f"{path}: unsupported image format '{ext}' (use .png, .tif, .tiff or .exr)")
    if bit_depth not in (8, 16):
        raise SplatglError(f"bit depth must be 8 or 16, got {bit_depth}")
    if ext in _FLOAT_FORMATS:
        pixels, fmt = np.ascontiguousarray(rgba, np.float32), oiio.FLOAT
        channels = ("R", "G", "B", "A")
        if depth is not None:
            pixels = np.ascontiguousarray(np.concatenate([pixels, depth[..., None]], -1), np.float32)
            channels += ("Z",)
    else:
        scale = 255.0 if bit_depth == 8 else 65535.0
        dtype = np.uint8 if bit_depth == 8 else np.uint16
        q = np.clip(rgba[..., :3], 0.0, 1.0) * scale + 0.5
        pixels = np.ascontiguousarray(q.astype(dtype))
        fmt = oiio.UINT8 if bit_depth == 8 else oiio.UINT16
        channels = ("R", "G", "B")
    h, w = pixels.shape[:2]
    spec = oiio.ImageSpec(w, h, len(channels), fmt)
    spec.channelnames = channels
    # Write beside the target and rename, so a failed write never leaves a half-written file.
    tmp = path.with_name(f".{path.stem}.partial{os.getpid()}{ext}")
    out = oiio.ImageOutput.create(str(tmp))
    if out is None:
        raise SplatglError(f"{path}: OpenImageIO cannot write this format ({oiio.geterror()})")
    try:
        if not out.open(str(tmp), spec) or not out.write_image(pixels):
            raise SplatglError(f"{path}: writing failed: {out.geterror()}")
        out.close()
        tmp.replace(path)
    finally:
        if tmp.exists():
            tmp.unlink()


def read_image(path: str | Path) -> np.ndarray:
    """(H, W, C) float32 pixels of an image file (integer formats scaled to [0, 1])."""
    inp = oiio.ImageInput.open(str(path))
    if inp is None:
        raise SplatglError(f"{path}: cannot read image ({oiio.geterror()})")
    try:
        return np.asarray(inp.read_image(oiio.FLOAT), np.float32)
    finally:
        inp.close()
