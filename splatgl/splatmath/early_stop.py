"""NumPy twins of early termination's GPU passes (:mod:`splatgl.renderers.early_stop` has the
algorithm and its accuracy): the mark pass (shaders/stop_mark.frag, :func:`stop_mask`), the
tile stop words (shaders/stop_tiles.comp, :func:`stop_tiles` from :func:`stop_blocks`), the
occlusion cull (shaders/occlusion_cull.comp, :func:`occlusion_cull`) and the coverage estimate
(shaders/coverage.comp, :func:`coverage`).
"""

from __future__ import annotations

import numpy as np

from .. import constants
from ..constants import STOP_BLOCK_SIZE, T_MIN, TILE_SIZE


def stop_mask(alpha: np.ndarray) -> np.ndarray:
    """(H, W) bool: pixels the mark pass stops, ``1 - A < T_MIN``, from (H, W) float32 A."""
    a = np.asarray(alpha, np.float32)
    return (np.float32(1.0) - a) < np.float32(T_MIN)


def stop_blocks(alpha: np.ndarray) -> np.ndarray:
    """(rows * 4, columns * 4) bool: ``STOP_BLOCK_SIZE``-square blocks all of whose in-image
    pixels are stopped, over the 16 x 16 tile grid (blocks past the image edge count as stopped)."""
    mask = stop_mask(alpha)
    h, w = mask.shape
    gh, gw = -(-h // TILE_SIZE), -(-w // TILE_SIZE)
    padded = np.ones((gh * TILE_SIZE, gw * TILE_SIZE), bool)
    padded[:h, :w] = mask
    n = TILE_SIZE // STOP_BLOCK_SIZE
    return padded.reshape(gh * n, STOP_BLOCK_SIZE, gw * n, STOP_BLOCK_SIZE).all(axis=(1, 3))


def stop_tiles(alpha: np.ndarray) -> np.ndarray:
    """(rows, columns) uint32 stop words of the 16 x 16 tiles, as shaders/stop_tiles.comp
    writes them: bit ``4 by + bx`` set when block (bx, by) of the tile is stopped
    (:func:`stop_blocks`); ``TILE_STOPPED`` when the whole tile is."""
    return pack_blocks(stop_blocks(alpha))


def pack_blocks(blocks: np.ndarray) -> np.ndarray:
    """(rows, columns) uint32 tile words from a (rows * 4, columns * 4) bool block grid."""
    n = TILE_SIZE // STOP_BLOCK_SIZE
    gh, gw = blocks.shape[0] // n, blocks.shape[1] // n
    per_tile = blocks.reshape(gh, n, gw, n).transpose(0, 2, 1, 3).reshape(gh, gw, n * n)
    weights = (np.uint32(1) << np.arange(n * n, dtype=np.uint32))
    return (per_tile.astype(np.uint32) * weights).sum(axis=2, dtype=np.uint32)


def unpack_blocks(tiles: np.ndarray) -> np.ndarray:
    """The inverse of :func:`pack_blocks`: the bool block grid of (rows, columns) tile words."""
    n = TILE_SIZE // STOP_BLOCK_SIZE
    gh, gw = tiles.shape
    bits = (np.asarray(tiles, np.uint32)[..., None] >> np.arange(n * n, dtype=np.uint32)) & 1
    return bits.astype(bool).reshape(gh, gw, n, n).transpose(0, 2, 1, 3).reshape(gh * n, gw * n)


def occlusion_cull(lo: np.ndarray, hi: np.ndarray, tiles: np.ndarray | None, width: int,
                   height: int) -> np.ndarray:
    """(M,) bool: which quads survive, from their pixel rectangles (M, 2) ``lo``/``hi``.

    A quad covers pixels within ``[floor(lo), floor(hi)]``; it is dropped when that range misses
    the image or (``tiles`` given, stop words as :func:`stop_tiles`) every block it touches is
    stopped and its tiles are at most ``constants.OCCLUSION_MAX_TILES`` (the shader's loop bound).
    """
    lo = np.asarray(lo, np.float64)
    hi = np.asarray(hi, np.float64)
    keep = ~((hi[:, 0] < 0) | (hi[:, 1] < 0) | (lo[:, 0] >= width) | (lo[:, 1] >= height))
    if tiles is None:
        return keep
    gh, gw = tiles.shape
    blocks = unpack_blocks(tiles)
    with np.errstate(invalid="ignore"):
        plo = np.floor(np.maximum(lo, 0.0))
        phi = np.minimum(np.floor(np.minimum(hi, [width, height])), [width - 1, height - 1])
    plo = np.nan_to_num(plo).astype(np.int64)
    phi = np.nan_to_num(phi).astype(np.int64)
    tlo = np.clip(plo // TILE_SIZE, 0, [gw - 1, gh - 1])
    thi = np.clip(phi // TILE_SIZE, 0, [gw - 1, gh - 1])
    blo = np.clip(plo // STOP_BLOCK_SIZE, 0, [blocks.shape[1] - 1, blocks.shape[0] - 1])
    bhi = np.clip(phi // STOP_BLOCK_SIZE, 0, [blocks.shape[1] - 1, blocks.shape[0] - 1])
    # Open blocks' 2D prefix sums: a range is all-stopped when it holds no open block.
    open_sum = np.zeros((blocks.shape[0] + 1, blocks.shape[1] + 1), np.int64)
    open_sum[1:, 1:] = np.cumsum(np.cumsum(~blocks, axis=0), axis=1)
    x0, y0, x1, y1 = blo[:, 0], blo[:, 1], bhi[:, 0] + 1, bhi[:, 1] + 1
    n_open = open_sum[y1, x1] - open_sum[y0, x1] - open_sum[y1, x0] + open_sum[y0, x0]
    walked = (thi[:, 0] - tlo[:, 0] + 1) * (thi[:, 1] - tlo[:, 1] + 1) <= constants.OCCLUSION_MAX_TILES
    nan = np.isnan(lo).any(axis=1) | np.isnan(hi).any(axis=1)
    return keep & ((n_open > 0) | ~walked | nan)


def coverage(lo: np.ndarray, hi: np.ndarray, area: np.ndarray, width: int, height: int) -> float:
    """Estimated fragments of quads with pixel rectangles (M, 2) ``lo``/``hi`` and areas (M,)
    ``area`` (pixels): each area times the share of its rectangle inside the image, at most the
    image's area (shaders/coverage.comp; non-finite or empty quads count 0)."""
    lo = np.asarray(lo, np.float64)
    hi = np.asarray(hi, np.float64)
    area = np.asarray(area, np.float64)
    size = hi - lo
    inside = np.maximum(np.minimum(hi, [width, height]) - np.maximum(lo, 0.0), 0.0)
    rect = size[:, 0] * size[:, 1]
    with np.errstate(invalid="ignore", divide="ignore"):
        share = np.where(rect > 0.0, inside[:, 0] * inside[:, 1] / rect, 0.0)
        each = np.minimum(area * share, float(width) * height)
    ok = np.isfinite(lo).all(axis=1) & np.isfinite(hi).all(axis=1) & (area > 0.0) & np.isfinite(each)
    return float(each[ok].sum())
