"""CPU sort stage: exact front-to-back order by view-space z.

Keys pack the float32 bits of z (positive after the near cull, so the bits order like the
values) above the splat index in one uint64; ``np.sort`` then gives a stable, exact 32-bit
depth order (ties keep input order, as the reference's stable radix sort does).
"""

from __future__ import annotations

import numpy as np


def depth_keys(depth: np.ndarray, indices: np.ndarray) -> np.ndarray:
    """(M,) uint64 keys ``(float_bits(z) << 32) | index`` for positive depths (M,)."""
    bits = np.ascontiguousarray(depth, dtype=np.float32).view(np.uint32).astype(np.uint64)
    return (bits << np.uint64(32)) | indices.astype(np.uint64)


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
    z = depth.astype(np.float64)
    lo, hi = z.min(), z.max()
    scale = (BUCKETS_16 - 1) / (hi - lo) if hi > lo else 0.0
    keys = np.minimum((z - lo) * scale, BUCKETS_16 - 1).astype(np.uint16)
    return indices[np.argsort(keys, kind="stable")].astype(np.uint32)
