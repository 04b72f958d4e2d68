"""NumPy twin of the device radix sort (:class:`splatgl.gl.radix_sort.RadixSorter`, shaders
radix_bits, radix_plan, radix_upsweep, radix_scan, radix_downsweep, radix_copy; the block
passes radix_block_*: ``bits=RADIX_BLOCK_BITS``): the same digits, the same passes and the
same rule for skipping digits in which no key differs."""

from __future__ import annotations

import numpy as np

from ..constants import RADIX_BITS

#: Buckets of one digit.
RADIX = 1 << RADIX_BITS


def radix_passes(keys: np.ndarray, bits: int = RADIX_BITS) -> list[int]:
    """Digit shifts of the passes that sort ``keys`` (M,) uint32 by ``bits``-bit digits, lowest
    digit first: from the lowest bit in which keys differ to the highest (radix_plan.comp's
    rule)."""
    if keys.size < 2:
        return []
    differ = int(np.bitwise_or.reduce(keys)) & ~int(np.bitwise_and.reduce(keys))
    if not differ:
        return []
    lo = (differ & -differ).bit_length() - 1
    return list(range(lo, differ.bit_length(), bits))


def radix_sort_twin(keys: np.ndarray, values: np.ndarray,
                    bits: int = RADIX_BITS) -> tuple[np.ndarray, np.ndarray]:
    """NumPy twin of :class:`splatgl.gl.radix_sort.RadixSorter`: ``(keys, values)`` (M,) uint32
    sorted by key, stably, by ``bits``-bit digits (RADIX_BLOCK_BITS: the block passes).

    Each pass reorders by one digit with a stable sort of the digit (what upsweep, scan and
    downsweep, or the block count, scan and scatter, compute on the device).
    """
    keys = np.ascontiguousarray(keys, np.uint32)
    values = np.ascontiguousarray(values, np.uint32)
    for shift in radix_passes(keys, bits):
        digit = (keys >> np.uint32(shift)) & np.uint32((1 << bits) - 1)
        perm = np.argsort(digit, kind="stable")
        keys, values = keys[perm], values[perm]
    return keys, values


def key_bits(keys: np.ndarray) -> np.ndarray:
    """(OR, AND) of ``keys`` (M,) uint32, M >= 1: what radix_bits.comp finds on the device."""
    return np.array([np.bitwise_or.reduce(keys), np.bitwise_and.reduce(keys)], np.uint32)
