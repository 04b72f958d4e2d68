"""CPU sort stage: exact front-to-back order by view-space z.

Keys pack the float32 bits of z (positive after the near cull, so the bits order like the
values) above the splat index in one uint64; ``np.sort`` then gives a stable, exact 32-bit
depth order (ties keep input order, as the reference's stable radix sort does).
"""

from __future__ import annotations

import sys

import numpy as np

if sys.byteorder != "little":  # keys are written as (low word, high word) uint32 pairs
    raise ImportError("splatgl.order.sort assumes a little-endian machine")


def depth_keys(depth: np.ndarray, indices: np.ndarray, out: np.ndarray | None = None
               ) -> np.ndarray:
    """(M,) uint64 keys ``(float_bits(z) << 32) | index`` for positive depths (M,) and uint32
    indices (M,), into ``out`` (M,) uint64 where given.

    Written as the keys' two little-endian uint32 words (two strided copies; half the time of
    widening, shifting and or-ing whole uint64 arrays).
    """
    keys = np.empty(len(depth), np.uint64) if out is None else out
    words = keys.view(np.uint32).reshape(-1, 2)
    words[:, 0] = indices
    words[:, 1] = np.asarray(depth, np.float32).view(np.uint32)
    return keys


def depth_sort(depth: np.ndarray, indices: np.ndarray) -> np.ndarray:
    """Indices (M,) uint32 reordered front to back by ``depth`` (M,) float, ties by index."""
    if depth.size and not (depth > 0).all():
        raise ValueError("depth_sort needs positive depths (cull at the near plane first)")
    keys = np.sort(depth_keys(depth, indices))
    return (keys & np.uint64(0xFFFFFFFF)).astype(np.uint32)


#: Number of depth buckets of :func:`bucket_sort` (16-bit keys).
BUCKETS_16 = 1 << 16


def bucket_sort(depth: np.ndarray, indices: np.ndarray) -> np.ndarray:
    """Approximate front-to-back order from 16-bit bucketed depth keys (M,) -> (M,) uint32.

    z is quantised linearly into 65536 buckets between the nearest and farthest depth, as
    web viewers' counting sorts do; splats sharing a bucket keep index order.  With a few
    very distant splats the buckets grow coarse and near splats tie (the DESIGN.md pitfall):
    this exists to measure that, not as a default.
    """
    if depth.size == 0:
        return indices.astype(np.uint32)
    return indices[np.argsort(bucket_keys(depth), kind="stable")].astype(np.uint32)


def bucket_keys(depth: np.ndarray) -> np.ndarray:
    """(M,) uint16 buckets of (M,) depths: ``floor((z - z_min) (65535 / (z_max - z_min)))``,
    computed in float64 (all 0 when the depths are equal).  The quad path's ``--sort
    bucket16`` and the reference's ``sort=bucket16`` emulation both use it."""
    if depth.size == 0:
        return np.zeros(0, np.uint16)
    z = depth.astype(np.float64)
    lo, hi = z.min(), z.max()
    scale = (BUCKETS_16 - 1) / (hi - lo) if hi > lo else 0.0
    return np.minimum((z - lo) * scale, BUCKETS_16 - 1).astype(np.uint16)
