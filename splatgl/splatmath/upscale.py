"""NumPy twin of shaders/upscale.frag: Catmull-Rom bicubic upscaling of a draft frame's
premultiplied ``(C, A)`` target, in float64 (the same sample positions, taps and clipping);
:class:`splatgl.interactive.upscale.Upscaler` runs the shader.
"""

from __future__ import annotations

import numpy as np


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
    filter of shaders/upscale.frag (along x, then along y); float64, clipped like the shader
    (last channel = alpha)."""
    img = np.asarray(image, np.float64)
    h, w = img.shape[:2]
    width, height = size
    ix, wx = _axis(w, width)
    iy, wy = _axis(h, height)
    rows = np.einsum("xk,yxkc->yxc", wx, img[:, ix])         # (h, W, C): along x
    out = np.einsum("yk,ykxc->yxc", wy, rows[iy])            # (H, W, C): along y
    out[..., :-1] = np.maximum(out[..., :-1], 0.0)
    out[..., -1] = np.clip(out[..., -1], 0.0, 1.0)
    return out
