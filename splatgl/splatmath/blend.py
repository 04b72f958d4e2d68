"""NumPy twin of the quad path's fragment stage and blending (shaders/quad.frag + blend state).

Dense and exact: every splat is evaluated at every pixel, so it is meant for small test scenes.
It applies the same per-fragment rules as the GPU (power > 0 and alpha < 1/255 discarded,
alpha clamped to 0.99, no early stop) and the same front-to-back blend
``dst = src (1 - dst.a) + dst``, optionally restricted to each splat's quad.
"""

from __future__ import annotations

import numpy as np

from ..constants import ALPHA_MAX, ALPHA_MIN


def pixel_centres(width: int, height: int, dtype=np.float64) -> tuple[np.ndarray, np.ndarray]:
    """(H, W) arrays of pixel-centre image coordinates u = j + 0.5, v = i + 0.5."""
    u = np.arange(width, dtype=dtype) + 0.5
    v = np.arange(height, dtype=dtype) + 0.5
    return np.meshgrid(u, v)


def splat_alpha(mean2d: np.ndarray, conic: np.ndarray, opacity: np.ndarray, width: int,
                height: int, quad_mask: np.ndarray | None = None) -> np.ndarray:
    """(N, H, W) fragment alpha of N splats (0 where the fragment is discarded).

    Args:
        mean2d: (N, 2) pixel centres of the splats.  conic: (N, 3) (a, b, c).
        opacity: (N,).  quad_mask: optional (N, H, W) bool, pixels covered by each quad.
    """
    u, v = pixel_centres(width, height, mean2d.dtype)
    dx = u[None] - mean2d[:, 0, None, None]
    dy = v[None] - mean2d[:, 1, None, None]
    a, b, c = (conic[:, k, None, None] for k in range(3))
    power = -0.5 * (a * dx * dx + c * dy * dy) - b * dx * dy
    alpha = np.minimum(ALPHA_MAX, opacity[:, None, None] * np.exp(np.minimum(power, 0.0)))
    keep = (power <= 0.0) & (alpha >= ALPHA_MIN)
    if quad_mask is not None:
        keep &= quad_mask
    return np.where(keep, alpha, 0.0)


def blend_front_to_back(alpha: np.ndarray, color: np.ndarray) -> np.ndarray:
    """Blend (N, H, W) alphas of splats sorted front to back with colours (N, 3).

    Returns (H, W, 4) premultiplied RGBA, as the GPU target holds it before compositing.
    """
    n, h, w = alpha.shape
    out = np.zeros((h, w, 4), alpha.dtype)
    for k in range(n):  # the blend recurrence, one splat (layer) at a time
        t = 1.0 - out[..., 3]
        out[..., :3] += (t * alpha[k])[..., None] * color[k]
        out[..., 3] += t * alpha[k]
    return out
