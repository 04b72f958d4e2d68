"""NumPy twin of the device radix sort (:class:`splatgl.gl.radix_sort.RadixSorter`, shaders
radix_bits, radix_plan, radix_upsweep, radix_scan, radix_downsweep, radix_copy): the same
digits, the same passes and the same rule for skipping digits in which no key differs."""

from __future__ import annotations

import numpy as np

from ..constants import RADIX_BITS

#: Buckets of one digit.
RADIX = 1 << RADIX_BITS


def radix_passes(keys: np.ndarray) -> list[int]:
    """Digit shifts of the passes that sort ``keys`` (M,) uint32, lowest digit first: from the
    lowest bit in which keys differ to the highest (radix_plan.comp's rule)."""
    if keys.size < 2:
        return []
    differ = int(np.bitwise_or.reduce(keys)) & ~int(np.bitwise_and.reduce(keys))
    if not differ:
        return []
    lo = (differ & -differ).bit_length() - 1
    return list(range(lo, differ.bit_length(), RADIX_BITS))


def radix_sort_twin(keys: np.ndarray, values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """NumPy twin of :class:`splatgl.gl.radix_sort.RadixSorter`: ``(keys, values)`` (M,) uint32 sorted by key, stably.

    Each pass reorders by one digit with a stable sort of the digit (what upsweep, scan and
    downsweep compute on the device).
    """
    keys = np.ascontiguousarray(keys, np.uint32)
    values = np.ascontiguousarray(values, np.uint32)
    for shift in radix_passes(keys):
        digit = ((keys >> np.uint32(shift)) & np.uint32(RADIX - 1)).astype(np.uint8)
        perm = np.argsort(digit, kind="stable")
        keys, values = keys[perm], values[perm]
    return keys, values


def key_bits(keys: np.ndarray) -> np.ndarray:
    """(OR, AND) of ``keys`` (M,) uint32, M >= 1: what radix_bits.comp finds on the device."""
    return np.array([np.bitwise_or.reduce(keys), np.bitwise_and.reduce(keys)], np.uint32)
