"""An INRIA PLY read by row ranges, for the out-of-core build (:mod:`splatgl.lod.external`):
binary files whose vertex rows are fixed-size records, read block by block into one buffer
(never the whole file), and the exact 1-99 % box of the centres found in two streaming passes.

The box must be exactly :func:`numpy.percentile`'s (``linear``), so that the Morton order, and
with it the hierarchy, is the one the in-memory build gives: each percentile is interpolated
between two order statistics, found exactly by a histogram of the upper 16 bits of the float32
values' order-preserving keys (first pass), then of the lower 16 bits within the bins that hold
them (second pass).
"""

from __future__ import annotations

import os
import re
from pathlib import Path

import numpy as np

from ..errors import SceneFormatError, SplatglError
from ..formats import ply
from ..formats.ply_header import parse_header
from ..scene.splats import Scene, SplatKind, activate

#: The percentiles of the box (:func:`splatgl.scene.spatial.morton_order_clamped_box`).
BOX_PERCENTILES = (1.0, 99.0)


class PlyRows:
    """The vertex rows of a binary PLY at ``path``: ``count``, ``dtype`` (one record),
    ``names``; :meth:`blocks` reads them in order, :meth:`scene` decodes a block."""

    def __init__(self, path: Path, surfels: bool = False):
        self.path = Path(path)
        try:
            with open(self.path, "rb") as fh:
                header = parse_header(self.path, fh)
                size = os.fstat(fh.fileno()).st_size
                names = {e.name for e in header.elements}
                if header.order is None or "vertex" not in names or "chunk" in names:
                    raise not_streamable(self.path)
                elem = next(e for e in header.elements if e.name == "vertex")
                if elem.has_list or any(n.startswith("packed_") for n, _ in elem.properties):
                    raise not_streamable(self.path)
                self.offset, self.dtype = ply._vertex_layout(self.path, header, size)
        except OSError as exc:
            raise SplatglError(f"{self.path}: cannot read: {exc.strerror or exc}") from None
        self.count = elem.count
        self.names = [n for n, _ in elem.properties]
        plan = ply._Columns(self.path, self.names, 0, self.dtype)  # required properties
        self.surfel = plan.surfel  # 2DGS: refused unless ``surfels`` (splatgl.edit.streamed)
        if plan.surfel and not surfels:
            raise SplatglError(f"{self.path}: level of detail needs 3DGS splats, this file holds "
                               "2DGS surfels")
        if self.count == 0:
            raise SceneFormatError(self.path, "the scene has no splats (element vertex 0)", "vertex")

    def blocks(self, rows: int):
        """``(start, records)`` of every block of at most ``rows`` rows, in order (one buffer,
        reused: a block is valid until the next)."""
        buf = np.empty(min(rows, self.count), self.dtype)
        try:
            with open(self.path, "rb") as fh:
                fh.seek(self.offset)
                start = 0
                while start < self.count:
                    block = buf[:min(rows, self.count - start)]
                    view = memoryview(block.view(np.uint8))
                    got = 0
                    while got < view.nbytes:
                        n = fh.readinto(view[got:])
                        if not n:
                            raise SceneFormatError(self.path, "file is truncated (or shrank while "
                                                   f"being read) at vertex row {start}", "vertex")
                        got += n
                    yield start, block
                    start += block.shape[0]
        except OSError as exc:
            raise SplatglError(f"{self.path}: cannot read: {exc.strerror or exc}") from None

    def scene(self, records: np.ndarray, first_row: int = 0) -> Scene:
        """The validated :class:`Scene` of ``records`` as :func:`splatgl.formats.ply.read`
        decodes them, less the extras (the level of detail keeps none)."""
        plan = ply._Columns(self.path, self.names, records.shape[0])
        plan.fill(records, 0)
        try:
            return activate(self.path, plan.means, plan.quats, plan.log_scales, plan.opacity,
                            plan.sh, SplatKind.GAUSSIAN_3D)
        except SceneFormatError as exc:
            if first_row:  # the index in the file, not in the block (the count is the block's)
                exc.args = (re.sub(r"first at index (\d+)",
                                   lambda m: f"first at index {first_row + int(m.group(1))}",
                                   str(exc)),)
            raise


def streamable(path: Path) -> bool:
    """Whether ``path`` is a binary PLY of fixed-size vertex rows (not the compressed PLY):
    what :class:`PlyRows` reads (other files are read whole)."""
    try:
        with open(path, "rb") as fh:
            head = fh.read(1 << 16)
    except OSError:
        return False  # the reader says why
    if not ply.sniff(head):
        return False
    text = head.split(b"end_header", 1)[0]
    return b"format binary_" in text and b" list " not in text


def not_streamable(path: Path) -> SplatglError:
    return SplatglError(f"{path}: the out-of-core level of detail reads binary INRIA PLY "
                        f"(fixed-size rows); convert it first: splatgl convert {path} -o "
                        f"{Path(path).with_suffix('.ply').name}")


def float_keys(values: np.ndarray) -> np.ndarray:
    """(N,) uint32 keys of float32 ``values`` in the same order (negatives flipped)."""
    u = np.ascontiguousarray(values, np.float32).view(np.uint32)
    return np.where(u & np.uint32(0x80000000), ~u, u | np.uint32(0x80000000))


def key_floats(keys: np.ndarray) -> np.ndarray:
    """The float32 values of :func:`float_keys`' keys."""
    k = np.asarray(keys, np.uint32)
    u = np.where(k & np.uint32(0x80000000), k & np.uint32(0x7FFFFFFF), ~k)
    return u.astype(np.uint32).view(np.float32)


class BoxFinder:
    """The exact percentile box of (N, 3) float32 centres seen block by block, twice:
    :meth:`add_first` every block, then :meth:`add_second` every block, then :meth:`box`."""

    def __init__(self, count: int):
        self.count = count
        self.high = np.zeros((3, 1 << 16), np.int64)
        self.ranks = []  # (rank lo, rank hi, gamma) of each percentile
        for p in BOX_PERCENTILES:
            q = np.true_divide(p, 100)
            virtual = (count - 1) * q  # numpy's 'linear'
            lo = int(np.clip(np.floor(virtual), 0, count - 1))
            hi = int(np.clip(lo + 1, 0, count - 1))
            self.ranks.append((lo, hi, virtual - np.floor(virtual)))
        self.bins = None  # per axis: {upper bin: (count before it, low histogram)}

    def add_first(self, means: np.ndarray) -> None:
        for axis in range(3):
            self.high[axis] += np.bincount(float_keys(means[:, axis]) >> np.uint32(16),
                                           minlength=1 << 16)

    def _plan_second(self) -> None:
        self.bins = []
        for axis in range(3):
            before = np.concatenate([[0], np.cumsum(self.high[axis])])
            wanted = {}
            for lo, hi, _ in self.ranks:
                for rank in (lo, hi):
                    b = int(np.searchsorted(before, rank, side="right") - 1)
                    wanted[b] = (int(before[b]), np.zeros(1 << 16, np.int64))
            self.bins.append(wanted)

    def add_second(self, means: np.ndarray) -> None:
        if self.bins is None:
            self._plan_second()
        for axis in range(3):
            keys = float_keys(means[:, axis])
            upper = keys >> np.uint32(16)
            for b, (_, hist) in self.bins[axis].items():
                sel = keys[upper == b]
                if sel.size:
                    hist += np.bincount(sel & np.uint32(0xFFFF), minlength=1 << 16)

    def _value(self, axis: int, rank: int) -> float:
        for b, (before, hist) in self.bins[axis].items():
            cum = before + np.cumsum(hist)
            if before <= rank < cum[-1]:
                low = int(np.searchsorted(cum, rank, side="right"))
                return float(key_floats(np.uint32((b << 16) | low)))
        raise AssertionError("rank outside the histogram")

    def box(self) -> tuple[np.ndarray, np.ndarray]:
        """(lo, hi) float64 (3,): ``np.percentile(means, (1, 99), axis=0)`` exactly."""
        if self.bins is None:
            self._plan_second()
        out = []
        for lo, hi, gamma in self.ranks:
            a = np.array([self._value(axis, lo) for axis in range(3)])
            b = np.array([self._value(axis, hi) for axis in range(3)])
            diff = b - a
            value = np.add(a, diff * gamma)  # numpy's _lerp
            if gamma >= 0.5:
                value = np.subtract(b, diff * (1 - gamma))
            out.append(value)
        return out[0], out[1]
