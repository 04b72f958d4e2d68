"""Device sort: a compute-shader LSD radix sort of 32-bit keys with a 32-bit payload.

Each pass sorts by one RADIX_BITS-bit digit in three dispatches (shaders/radix_count.comp,
radix_scan.comp, radix_scatter.comp; the layout is in shaders/lib/radix.glsl): per-tile digit
counts, one exclusive scan over all (digit, tile) counts, and a stable scatter.  Every pass is
stable, so the whole sort is: equal keys keep their input order.  Fed the cull's ascending
indices with the float32 bits of their depths, it gives exactly :func:`splatgl.order.sort.depth_sort`'s
order (ties by index), which the tests check bit for bit.

Passes above the highest bit in which the smallest and largest key differ are skipped: every key
between them shares those bits, so those passes would move nothing.

:func:`radix_sort_twin` is the NumPy twin: the same digits, passes and skip rule.
"""

from __future__ import annotations

import moderngl
import numpy as np

from ..constants import RADIX_BITS, RADIX_ITEMS
from .bindings import (RADIX_BINDING_HIST, RADIX_BINDING_KEYS_IN, RADIX_BINDING_KEYS_OUT,
                       RADIX_BINDING_VALS_IN, RADIX_BINDING_VALS_OUT, RADIX_GROUP)
from .shaders import ProgramCache

#: Keys one work group sorts per pass.
TILE_KEYS = RADIX_GROUP * RADIX_ITEMS
RADIX = 1 << RADIX_BITS


def radix_passes(keys: np.ndarray) -> list[int]:
    """Bit shifts of the passes that can reorder ``keys`` (M,) uint32, lowest digit first."""
    if keys.size < 2:
        return []
    differ = int(keys.min()) ^ int(keys.max())
    top = differ.bit_length()  # every key shares the bits at and above ``top``
    return [shift for shift in range(0, 32, RADIX_BITS) if shift < top]


def radix_sort_twin(keys: np.ndarray, values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """NumPy twin of :class:`RadixSorter`: ``(keys, values)`` (M,) uint32 sorted by key, stably.

    Each pass reorders by one digit with a stable sort of the digit (what count, scan and
    scatter compute on the device).
    """
    keys = np.ascontiguousarray(keys, np.uint32)
    values = np.ascontiguousarray(values, np.uint32)
    for shift in radix_passes(keys):
        digit = ((keys >> np.uint32(shift)) & np.uint32(RADIX - 1)).astype(np.uint8)
        perm = np.argsort(digit, kind="stable")
        keys, values = keys[perm], values[perm]
    return keys, values


class RadixSorter:
    """Sorts (M,) uint32 keys with uint32 values on the device; reuse it, then :meth:`release`.

    Buffers grow to the largest M seen and are kept between calls.
    """

    def __init__(self, ctx: moderngl.Context, programs: ProgramCache | None = None):
        self.ctx = ctx
        self.programs = programs or ProgramCache(ctx)
        self._capacity = 0
        self._bufs: list[moderngl.Buffer] = []  # keys A, values A, keys B, values B, hist

    def _reserve(self, count: int) -> None:
        if count <= self._capacity:
            return
        for buf in self._bufs:
            buf.release()
        tiles = -(-count // TILE_KEYS)
        self._bufs = [self.ctx.buffer(reserve=4 * count) for _ in range(4)]
        self._bufs.append(self.ctx.buffer(reserve=4 * RADIX * tiles))
        self._capacity = count

    def sort(self, keys: np.ndarray, values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(keys, values)`` (M,) uint32, sorted by key, equal keys in input order."""
        keys = np.ascontiguousarray(keys, np.uint32)
        values = np.ascontiguousarray(values, np.uint32)
        count = keys.size
        passes = radix_passes(keys)
        if not passes:
            return keys.copy(), values.copy()
        self._reserve(count)
        src, dst = self.sort_on_device(keys, values, passes)
        return (np.frombuffer(src[0].read(4 * count), np.uint32),
                np.frombuffer(src[1].read(4 * count), np.uint32))

    def sort_on_device(self, keys: np.ndarray, values: np.ndarray, passes: list[int]):
        """Upload, run ``passes``; returns ((keys, values) buffers holding the result, the other
        pair).  The result stays on the device (a draw can bind it as its index buffer)."""
        count = keys.size
        k_a, v_a, k_b, v_b, hist = self._bufs
        k_a.write(keys.tobytes())
        v_a.write(values.tobytes())
        tiles = -(-count // TILE_KEYS)
        count_prog = self.programs.compute("radix_count.comp")
        scan_prog = self.programs.compute("radix_scan.comp")
        scatter_prog = self.programs.compute("radix_scatter.comp")
        for prog in (count_prog, scan_prog, scatter_prog):
            for name, value in (("u_count", count), ("u_tiles", tiles)):
                if name in prog:
                    prog[name].value = value
        src, dst = (k_a, v_a), (k_b, v_b)
        hist.bind_to_storage_buffer(RADIX_BINDING_HIST)
        for shift in passes:
            src[0].bind_to_storage_buffer(RADIX_BINDING_KEYS_IN)
            src[1].bind_to_storage_buffer(RADIX_BINDING_VALS_IN)
            dst[0].bind_to_storage_buffer(RADIX_BINDING_KEYS_OUT)
            dst[1].bind_to_storage_buffer(RADIX_BINDING_VALS_OUT)
            for prog in (count_prog, scan_prog, scatter_prog):
                if "u_shift" in prog:
                    prog["u_shift"].value = shift
            count_prog.run(group_x=tiles)
            self.ctx.memory_barrier()
            scan_prog.run(group_x=1)
            self.ctx.memory_barrier()
            scatter_prog.run(group_x=tiles)
            self.ctx.memory_barrier()
            src, dst = dst, src
        return src, dst

    def release(self) -> None:
        for buf in self._bufs:
            buf.release()
        self._bufs = []
        self._capacity = 0


def device_depth_sort(sorter: RadixSorter, depth: np.ndarray, indices: np.ndarray) -> np.ndarray:
    """:func:`splatgl.order.sort.depth_sort` on the device: indices (M,) uint32 front to back by
    ``depth`` (M,) (positive, so its float32 bits order like the values), ties in input order
    (the cull's ascending indices: ties by index, as the CPU sort)."""
    if depth.size and not (depth > 0).all():
        raise ValueError("device_depth_sort needs positive depths (cull at the near plane first)")
    keys = np.ascontiguousarray(depth, np.float32).view(np.uint32)
    return sorter.sort(keys, indices)[1]
