"""SPZ attribute bytes to values: positions and the two rotation encodings (:mod:`.spz`)."""

from __future__ import annotations

import math

import numpy as np


def positions(raw: np.ndarray, version: int, fractional_bits: int) -> np.ndarray:
    """(N, 3) float64 from (N, 9) uint8 24-bit signed fixed point (version 1: (N, 6) float16)."""
    if version == 1:
        return raw.copy().view("<f2").astype(np.float64)
    b = raw.reshape(-1, 3, 3).astype(np.int32)
    fixed = b[..., 0] | (b[..., 1] << 8) | (b[..., 2] << 16)
    fixed = np.where(fixed & 0x800000, fixed - (1 << 24), fixed)
    return fixed * 2.0 ** -fractional_bits


def unpack_rotation_xyz(raw: np.ndarray) -> np.ndarray:
    """(N, 4) float64 (w, x, y, z) from (N, 3) uint8 x, y, z (versions 1-2), w >= 0."""
    xyz = raw / 127.5 - 1.0
    w = np.sqrt(np.maximum(0.0, 1.0 - (xyz * xyz).sum(axis=1)))
    return np.concatenate([w[:, None], xyz], axis=1)


def unpack_rotation_smallest3(raw: np.ndarray) -> np.ndarray:
    """(N, 4) float64 (w, x, y, z) from (N, 4) uint8 smallest-three words (versions 3-4)."""
    b = raw.astype(np.uint32)
    word = b[:, 0] | (b[:, 1] << 8) | (b[:, 2] << 16) | (b[:, 3] << 24)
    largest = (word >> 30).astype(np.intp)
    xyzw = np.zeros((raw.shape[0], 4))
    for i in range(3, -1, -1):
        mine = largest != i
        value = (word & 511) / 511.0 * math.sqrt(0.5)
        value = np.where((word >> 9) & 1, -value, value)
        xyzw[:, i] = np.where(mine, value, 0.0)
        word = np.where(mine, word >> 10, word)
    rows = np.arange(raw.shape[0])
    xyzw[rows, largest] = np.sqrt(np.maximum(0.0, 1.0 - (xyzw * xyzw).sum(axis=1)))
    return xyzw[:, [3, 0, 1, 2]]
