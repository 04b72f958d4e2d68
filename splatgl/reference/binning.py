"""Reference stages 2-4: ``emit_keys``, ``sort`` and ``tile_ranges`` (3DGS's duplicateWithKeys,
radix sort and identifyTileRanges).

Key layout (DESIGN.md section 2): ``key = (tile_id << 32) | float32_bits(view z)`` as uint64 with
``tile_id = y * tiles_x + x`` (the per-pixel order: the depth of the splat's peak along the ray
where it is nearest to the tile, :func:`splatgl.splatmath.peak.tile_key_bits`).  View z is positive after near culling, so its IEEE bits order like
the depths.  Keys are emitted splat by splat in index order (within a splat, tile rows top to
bottom, each left to right) and sorted stably, so equal keys keep splat-index order.
"""

from __future__ import annotations

import numpy as np

from ..constants import TILE_SIZE
from ..splatmath.peak import tile_key_bits
from .stages import ProjectedSplats


def depth_bits(depth: np.ndarray) -> np.ndarray:
    """(N,) view z (any float dtype) -> (N,) uint64 holding the float32 bit pattern."""
    return np.ascontiguousarray(depth, dtype=np.float32).view(np.uint32).astype(np.uint64)


def emit_keys(proj: ProjectedSplats) -> tuple[np.ndarray, np.ndarray]:
    """One (key, splat index) pair for every tile of every visible splat's rectangle.

    Returns ``(keys (M,) uint64, splat_index (M,) int64)``, M = sum of ``tiles_touched``, in
    emission order: splats by index; within a splat, tiles row by row.
    """
    counts = proj.tiles_touched
    total = int(counts.sum())
    idx = np.repeat(np.arange(proj.count, dtype=np.int64), counts)
    first = np.cumsum(counts) - counts
    local = np.arange(total, dtype=np.int64) - first[idx]
    wide = (proj.rect_max[:, 0] - proj.rect_min[:, 0])[idx]
    x = proj.rect_min[idx, 0] + local % np.maximum(wide, 1)
    y = proj.rect_min[idx, 1] + local // np.maximum(wide, 1)
    tile = (y * proj.grid[0] + x).astype(np.uint64)
    if proj.peak is not None and proj.rays is not None:    # per-pixel order: depth at the tile
        low = tile_key_bits(proj.peak[idx], proj.mean2d[idx], x, y, proj.rays, TILE_SIZE)
    else:
        low = (depth_bits(proj.depth) if proj.key_bits is None else proj.key_bits)[idx]  # emulated
    keys = (tile << np.uint64(32)) | low
    return keys, idx


def sort(keys: np.ndarray, values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Stable sort of (M,) uint64 keys carrying (M,) values; equal keys keep their input order.

    Returns ``(sorted_keys, sorted_values)``.
    """
    order = np.argsort(keys, kind="stable")
    return keys[order], values[order]


def tile_ranges(sorted_keys: np.ndarray, n_tiles: int) -> np.ndarray:
    """(n_tiles, 2) int64 ``[start, end)`` of every tile's run in the sorted list (empty: equal)."""
    tiles = (sorted_keys >> np.uint64(32)).astype(np.int64)
    ids = np.arange(n_tiles, dtype=np.int64)
    return np.stack([np.searchsorted(tiles, ids, "left"), np.searchsorted(tiles, ids, "right")], 1)
