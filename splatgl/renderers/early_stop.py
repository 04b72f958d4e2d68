"""Early termination for the quad path: stop shading pixels that are already opaque.

``coverage`` (shaders/coverage.comp) first estimates the fragments a plain draw would
rasterise.  With ``--early-stop on`` the sorted splats are then drawn in batches
(:func:`batch_bounds`, COARSE_SCHEDULE or, for views of very large quads, FINE_SCHEDULE); with
``auto`` (the default) only views of large quads over an overdrawn image are
(``constants.EARLY_STOP_MIN_QUAD_FRAGMENTS``, ``EARLY_STOP_MIN_OVERDRAW``), and the other views
get one plain draw.  Between batches:

1. ``mark`` (shaders/stop_mark.*): a full-screen pass writes depth 0 wherever the accumulated
   transmittance ``T = 1 - A`` is below ``T_MIN`` (the reference's stop threshold); splat quads
   sit at depth 0.5 and are drawn with ``depth < stored`` and ``early_fragment_tests``, so their
   fragments on marked pixels are rejected before shading.
2. ``stop_tiles`` (shaders/stop_tiles.comp): one word per 16 x 16 tile, a bit per 4 x 4 block
   whose pixels are all marked.
3. ``occlusion_cull`` (shaders/occlusion_cull.comp): the next batch's splats whose quad
   rectangle lies only on stopped blocks are dropped, the survivors compacted in order, one
   draw command per SEGMENT slots, and the batch is drawn with one multi-draw-indirect.

Accuracy (DESIGN.md section 2 and docs/early-stop.md).  A pixel is marked only after a batch
ends with ``T < T_MIN``.  The reference adds splat k while ``T_k (1 - alpha_k) >= T_MIN``, so
while it still adds splats the running T is at least T_MIN and the pixel is not marked: the
quad path receives every splat the reference blends, plus, on pixels the reference stopped,
the splats up to the end of the batch where T fell below T_MIN.  Their total weight is
``T_stop - T_end <= T_stop < T_MIN / (1 - ALPHA_MAX) = 0.01`` (``T_stop``: the reference's T
when it stopped), a prefix of what the quad path added before (no stop at all), so each pixel's
error against the reference is at most ``0.01 max|c - bg|`` and never more weight than without
the stop.  The occlusion cull drops only splats whose every fragment the depth test would
reject, so it changes no pixel.  On 8- and 16-bit targets ``1 - A < 1e-4`` holds only
where ``A`` is stored as exactly 1, where blending adds nothing anyway: the image is unchanged.

NumPy twins: :func:`stop_mask`, :func:`stop_tiles` (:func:`stop_blocks`), :func:`occlusion_cull`,
:func:`coverage`.
"""

from __future__ import annotations

import math
from typing import Callable

import numpy as np

from .. import constants
from ..constants import STOP_BLOCK_SIZE, T_MIN, TILE_SIZE
from ..gl.bindings import OCCLUSION_GROUP, OCCLUSION_PER_INVOCATION

#: Slots per draw command of the occlusion cull (one work group of occlusion_cull.comp).
SEGMENT = OCCLUSION_GROUP * OCCLUSION_PER_INVOCATION
#: Bytes per draw command: DrawArraysIndirectCommand (count, instanceCount, first, baseInstance)
#: and one padding uint, since moderngl's render_indirect uses a 20-byte stride for arrays too.
COMMAND_BYTES = 20
#: A tile's stop word when all its blocks are stopped (16 blocks, shaders/stop_tiles.comp).
TILE_STOPPED = (1 << (TILE_SIZE // STOP_BLOCK_SIZE) ** 2) - 1
#: The fewest invocations shaders/coverage.comp runs with (each sums every stride-th slot;
#: llvmpipe ends an invocation's loops after 65535 iterations, so the invocations grow with the
#: count beyond COVERAGE_SLOTS_PER_INVOCATION slots each).
COVERAGE_MIN_INVOCATIONS = 1024
COVERAGE_SLOTS_PER_INVOCATION = 16384

#: Batch schedules (chosen by measurement, docs/early-stop.md), (first share, growth): the first
#: batch holds that share of the sorted splats (at least MIN_BATCH), each next one GROWTH times
#: the previous.  Each batch boundary costs llvmpipe the overlap of its single-threaded per-quad
#: work with rasterisation and saves shading in proportion to fragments, so views of large
#: quads (``constants.EARLY_STOP_FINE_QUAD_FRAGMENTS`` per quad and more) take the fine schedule
#: (about 8 batches), the others the coarse one (3 batches: 1/8, 5/16, the rest).
COARSE_SCHEDULE = (1.0 / 8.0, 2.5)
FINE_SCHEDULE = (1.0 / 64.0, 1.6)
FIRST_BATCH_FRACTION, GROWTH = COARSE_SCHEDULE
MIN_BATCH = 512
#: No batch is longer than this (a long draw stays interruptible between batches; with early
#: termination off, the draw is split into batches of this size only).
MAX_BATCH = 1 << 20

#: ``on_batch(done, total)``: called after each batch with the sorted splats drawn so far; it may
#: raise (KeyboardInterrupt) to abandon the frame.
BatchHook = Callable[[int, int], None]


def batch_bounds(count: int, first_fraction: float = FIRST_BATCH_FRACTION, growth: float = GROWTH,
                 min_batch: int = MIN_BATCH, max_batch: int = MAX_BATCH) -> list[int]:
    """Batch boundaries ``[0, e_0, e_1, ..., count]`` of a geometric schedule.

    The first batch has ``max(min_batch, ceil(count * first_fraction))`` splats, each next one
    ``growth`` times as many, none more than ``max_batch``.  ``growth`` <= 1 gives equal batches.
    """
    bounds = [0]
    size = float(max(min_batch, math.ceil(count * first_fraction)))
    while bounds[-1] < count:
        step = int(min(max_batch, max(1, size)))
        bounds.append(min(count, bounds[-1] + step))
        size *= max(growth, 1.0)
    return bounds


def plain_bounds(count: int, max_batch: int = MAX_BATCH) -> list[int]:
    """Boundaries of the draw without early termination: batches of ``max_batch``."""
    return list(range(0, count, max_batch)) + [count] if count else [0]


# ----------------------------------------------------------------------------- NumPy twins
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
