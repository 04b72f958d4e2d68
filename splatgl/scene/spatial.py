"""Spatial orders of splat centres: two Morton (Z-curve) orders, kept apart on purpose.

- :func:`morton_order_clamped_box`: 21 bits per axis over the 1-99 % box of the points (outliers
  clamped to its faces), so a few far splats do not squash the rest into a few cells.  The
  level-of-detail leaves (:mod:`splatgl.lod.build`) and the cull's chunks
  (:mod:`splatgl.order.chunks`) are made of consecutive rows in this order.
- :func:`morton_order_full_box`: ``bits`` (10) bits per axis over the whole bounding box, the
  order the compressed PLY and SOG writers store splats in (:mod:`splatgl.formats`): their
  chunk bounds and textures follow it, so changing it changes the files they write.

Both sort stably, so equal codes keep their row order.
"""

from __future__ import annotations

import numpy as np


def morton_order_clamped_box(points: np.ndarray) -> np.ndarray:
    """(N,) int64 permutation putting (N, 3) points in Morton order over their 1-99% box
    (outliers clamped to the box's faces); 21 bits per axis."""
    lo = np.percentile(points, 1.0, axis=0)
    hi = np.percentile(points, 99.0, axis=0)
    return np.argsort(morton_codes_clamped(points, lo, hi), kind="stable")


def morton_codes_clamped(points: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """(N,) uint64 Morton codes (21 bits per axis, 63 in all) of (N, 3) float64 points over the
    box ``lo..hi`` (outliers clamped to its faces): :func:`morton_order_clamped_box`'s codes,
    which the out-of-core level of detail (:mod:`splatgl.lod.external`) computes block by block
    over the box it found in a streaming pass."""
    span = np.where(hi > lo, hi - lo, 1.0)
    with np.errstate(invalid="ignore"):  # non-finite points: NaN here, placed first below
        q = np.clip((points - lo) / span, 0.0, 1.0)
    q = (np.nan_to_num(q, nan=0.0) * ((1 << 21) - 1)).astype(np.uint64)
    code = np.zeros(points.shape[0], np.uint64)
    for axis in range(3):
        v = q[:, axis]
        v = (v | (v << np.uint64(32))) & np.uint64(0x1F00000000FFFF)
        v = (v | (v << np.uint64(16))) & np.uint64(0x1F0000FF0000FF)
        v = (v | (v << np.uint64(8))) & np.uint64(0x100F00F00F00F00F)
        v = (v | (v << np.uint64(4))) & np.uint64(0x10C30C30C30C30C3)
        v = (v | (v << np.uint64(2))) & np.uint64(0x1249249249249249)
        code |= v << np.uint64(axis)
    return code


def morton_order_full_box(means: np.ndarray, bits: int = 10) -> np.ndarray:
    """(N,) intp permutation sorting ``means`` (N, 3) along a Morton (Z-order) curve of
    ``bits`` bits per axis over their bounding box.  Writers that chunk or texture the splats use
    it so neighbours share bounds (tighter chunk quantisation, smaller WebP files)."""
    m = np.asarray(means, np.float64)
    return np.argsort(box_morton_codes(m, m.min(axis=0), m.max(axis=0), bits), kind="stable")


def box_morton_codes(means: np.ndarray, lo: np.ndarray, hi: np.ndarray, bits: int = 10) -> np.ndarray:
    """(N,) int64 Morton codes of ``means`` (N, 3), ``bits`` bits per axis over the box
    ``lo..hi`` (x the most significant of each bit triple): the order of
    :func:`morton_order_full_box` when the box is the centres' own."""
    m = np.asarray(means, np.float64)
    span = np.where(hi > lo, hi - lo, 1.0)
    cells = np.clip(((m - lo) / span * ((1 << bits) - 1)).astype(np.int64), 0, (1 << bits) - 1)
    code = np.zeros(m.shape[0], np.int64)
    for bit in range(bits):
        for axis in range(3):
            code |= ((cells[:, axis] >> bit) & 1) << (3 * bit + (2 - axis))
    return code
