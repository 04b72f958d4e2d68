"""One chunk of a tile's splat list on the tile's 256 pixels: the per-pixel alpha of K splats
and their front-to-back blending, as (tiles, K, 256) arrays.  The reference rasterizer's
arithmetic (DESIGN.md 2), shared by both orders of :func:`splatgl.reference.rasterize.rasterize`
(the global order blends each tile's list chunk by chunk; the per-pixel order,
:mod:`splatgl.reference.per_pixel`, re-sorts each pixel's contributions first) and by the
single-pixel trace (:mod:`splatgl.reference.pixel`).
"""

from __future__ import annotations

import numpy as np

from ..constants import ALPHA_MIN, T_MIN, TILE_SIZE
from ..splatmath import surfel as sf
from . import emulation
from .options import Compat
from .stages import ProjectedSplats

#: Pixels per tile.
TILE_PIXELS = TILE_SIZE * TILE_SIZE


def tile_centres(tiles: np.ndarray, proj: ProjectedSplats) -> tuple[np.ndarray, np.ndarray]:
    """Pixel-centre coordinates ``j + 0.5`` of the columns and rows of tiles ``tiles`` (b,), as
    two (b, 16) arrays in the projection dtype."""
    lanes = np.arange(TILE_SIZE, dtype=np.float64) + 0.5
    gw = proj.grid[0]
    tiles = np.asarray(tiles)[:, None]
    return (((tiles % gw) * TILE_SIZE + lanes).astype(proj.dtype),
            ((tiles // gw) * TILE_SIZE + lanes).astype(proj.dtype))


def tile_outputs(b: int, dtype) -> tuple[np.ndarray, ...]:
    """Per-pixel outputs of ``b`` tiles at their start values: T (b, 256) ones, C (b, 256, 3),
    D (b, 256) zeros, n_contrib and n_blended (b, 256) int32 zeros."""
    return (np.ones((b, TILE_PIXELS), dtype), np.zeros((b, TILE_PIXELS, 3), dtype),
            np.zeros((b, TILE_PIXELS), dtype), np.zeros((b, TILE_PIXELS), np.int32),
            np.zeros((b, TILE_PIXELS), np.int32))


def gaussian_power(conic: np.ndarray, dx: np.ndarray, dy: np.ndarray) -> np.ndarray:
    """``-0.5 (a dx^2 + c dy^2) - b dx dy`` with ``conic[..., 0:3] = (a, b, c)`` (broadcast)."""
    a, b, c = conic[..., 0], conic[..., 1], conic[..., 2]
    half = np.asarray(-0.5, dtype=np.result_type(conic, dx))
    return half * (a * dx * dx + c * dy * dy) - b * dx * dy


def gaussian_alpha(power: np.ndarray, opacity: np.ndarray, alpha_max: float,
                   alpha_min: float = ALPHA_MIN) -> np.ndarray:
    """``min(alpha_max, o exp(power))``, 0 where ``power > 0`` or the result is below
    ``alpha_min`` (1/255; the ``min_alpha`` emulation knob changes it)."""
    dt = np.result_type(power, opacity).type
    with np.errstate(over="ignore"):
        alpha = np.minimum(dt(alpha_max), opacity * np.exp(power))
    return np.where((power <= 0) & (alpha >= dt(alpha_min)), alpha, dt(0.0))


class ChunkSplats:
    """Per-tile splat data gathered for one chunk: everything :func:`blend_chunk` reads."""

    def __init__(self, proj: ProjectedSplats, values: np.ndarray, pos: np.ndarray,
                 valid: np.ndarray):
        sidx = values[np.minimum(pos, values.shape[0] - 1)]
        self.mean2d = proj.mean2d[sidx]      # (n, K, 2)
        self.conic = proj.conic[sidx]        # (n, K, 3)
        self.opacity = proj.opacity[sidx]    # (n, K)
        self.color = proj.color[sidx]        # (n, K, 3)
        self.depth = proj.depth[sidx]        # (n, K)
        self.valid = valid                   # (n, K)
        self.sidx = sidx                     # (n, K) projected rows
        self.wrap_period = proj.wrap_period  # equirect: reach half a turn each side
        if proj.is_surfel:
            self.rows = proj.surfel_rows[sidx]       # (n, K, 3, 3)
            self.depth_rows = proj.depth_rows[sidx]  # (n, K, 3)
        # Emulation (reference/emulation.py): an extent knob's per-pixel clip.
        self.clip_q = None if proj.clip_q is None else proj.clip_q[sidx]           # (n, K)
        self.clip_rows = None if proj.clip_rows is None else proj.clip_rows[sidx]  # (n, K, 2, 2)


def chunk_alpha(g: ChunkSplats, px: np.ndarray, py: np.ndarray, alpha_max: float,
                alpha_min: float = ALPHA_MIN) -> np.ndarray:
    """(n, K, 256) alpha of K splats on the 256 pixels of n tiles (0 where skipped).

    ``px``, ``py``: (n, 16) pixel-centre coordinates of each tile's columns and rows.  The
    quadratic form is separable per axis, so the x and y terms are built on 16 lanes and
    combined with the same operation order as the serial formula.
    """
    dt = px.dtype.type
    dx = px[:, None, :] - g.mean2d[:, :, 0, None]          # (n, K, 16) by column
    dy = py[:, None, :] - g.mean2d[:, :, 1, None]          # (n, K, 16) by row
    axx = g.conic[:, :, 0, None] * dx * dx
    cyy = g.conic[:, :, 2, None] * dy * dy
    bx = g.conic[:, :, 1, None] * dx
    power = dt(-0.5) * (axx[:, :, None, :] + cyy[:, :, :, None]) - bx[:, :, None, :] * dy[:, :, :, None]
    n, k = dx.shape[:2]
    if g.clip_q is not None or g.clip_rows is not None:   # an extent emulation knob
        keep = emulation.clip_mask(power, dx, dy, g.clip_q, g.clip_rows)
        power = np.where(keep, power, dt(-np.inf))
    alpha = gaussian_alpha(power.reshape(n, k, TILE_PIXELS), g.opacity[:, :, None], alpha_max,
                           alpha_min)
    if g.wrap_period is not None:   # equirect: |dx| <= period / 2 (splatgl/cameras/equirect.py)
        reach = np.abs(dx) <= dt(0.5 * g.wrap_period)                  # (n, K, 16) by column
        alpha = np.where(np.broadcast_to(reach[:, :, None, :], power.shape).reshape(n, k, TILE_PIXELS),
                         alpha, dt(0.0))
    return np.where(g.valid[:, :, None], alpha, dt(0.0))


def surfel_chunk_alpha(g: ChunkSplats, px: np.ndarray, py: np.ndarray, alpha_max: float,
                       convention: Compat = Compat.INRIA, alpha_min: float = ALPHA_MIN
                       ) -> tuple[np.ndarray, np.ndarray]:
    """2DGS: (n, K, 256) alpha (0 where skipped) and (n, K, 256) view z of the hit.

    :func:`splatgl.splatmath.surfel.surfel_alpha` on the tile's pixel centres, as (n, K, 16 rows,
    16 columns) broadcasts: ``h_u`` varies along columns only, ``h_v`` along rows only.
    """
    dt = px.dtype.type
    dx = (px[:, None, :] - g.mean2d[:, :, 0, None])[:, :, None, :]   # (n, K, 1, 16) by column
    dy = (py[:, None, :] - g.mean2d[:, :, 1, None])[:, :, :, None]   # (n, K, 16, 1) by row
    alpha, z = sf.surfel_alpha(g.rows[:, :, None, None], g.depth_rows[:, :, None, None],
                               g.opacity[:, :, None, None], dx, dy, alpha_max, convention)
    n, k = g.opacity.shape
    alpha = np.broadcast_to(alpha, (n, k, TILE_SIZE, TILE_SIZE)).reshape(n, k, TILE_PIXELS)
    z = np.broadcast_to(z, (n, k, TILE_SIZE, TILE_SIZE)).reshape(n, k, TILE_PIXELS)
    if alpha_min > ALPHA_MIN:                     # the min_alpha emulation knob
        alpha = np.where(alpha >= dt(alpha_min), alpha, dt(0.0))
    return np.where(g.valid[:, :, None], alpha, dt(0.0)), z


def blend_chunk(t_prev: np.ndarray, alpha: np.ndarray, inclusive_stop: bool
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Blend one chunk: (n, 256) running T, (n, K, 256) alphas (0 for skipped or stopped).

    Returns ``(weights (n, K, 256) = alpha T for blended splats, 0 otherwise,
    n_blended (n, 256) prefix length kept, t_seq (n, K + 1, 256))`` where ``t_seq[:, 0]`` is
    ``t_prev`` and ``t_seq[:, k + 1]`` the running product after splat k (before the stop test).
    """
    n, k, p = alpha.shape
    t_seq = np.empty((n, k + 1, p), alpha.dtype)
    t_seq[:, 0] = t_prev
    np.subtract(alpha.dtype.type(1.0), alpha, out=t_seq[:, 1:])
    np.cumprod(t_seq, axis=1, out=t_seq)
    t_min = alpha.dtype.type(T_MIN)
    kept = t_seq[:, 1:] > t_min if inclusive_stop else t_seq[:, 1:] >= t_min
    weights = np.where(kept, alpha, alpha.dtype.type(0.0)) * t_seq[:, :-1]
    return weights, kept.sum(axis=1), t_seq
