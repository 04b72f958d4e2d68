"""Lazy reading of a ``.lod.ply`` (issue 41 item 2): open it by its header alone, read only the
pages of node spheres a cut tests and the node rows it draws.

The file's layout (:mod:`splatgl.lod.io`) makes this cheap: the tree is implicit (level offsets
from the leaf count and the branching, children of node ``j`` at ``j * B ..``), levels are
stored coarse after fine in Morton order, so a subtree is one contiguous row range per level,
and the ``lod_bound`` element holds every node's sphere (16 bytes).  A cut walks from the root
(:func:`splatgl.lod.cut.select_cut_weights`, here over arrays that read their pages on first
use): a far view reads the few top levels' spheres and the rows it draws, whatever the file's
size.  :attr:`LazyLod.bytes_read` counts what was read.

    lod = LazyLod("city.lod.ply")
    rows, weights = lod.cut(camera, LodSettings(threshold_px=1))
    scene = lod.cut_scene(camera)      # the cut as a plain Scene any renderer draws
"""

from __future__ import annotations

import mmap
import os
from pathlib import Path

import numpy as np

from ..cameras.camera import Camera
from ..errors import SceneFormatError
from ..formats import ply
from ..scene.splats import Scene, activate
from .build import level_offsets
from .cut import CutData, select_cut_weights
from .cut_budget import select_cut_budget
from ..formats.metadata import header_box
from .io import BOUNDS, ELEMENT, stored_anchor, stored_branching
from .selection import LodSettings

#: Node spheres per page (16 bytes each: 4 KiB), the unit they are read in.
BOUND_PAGE = 256
#: Pages of spheres read and decoded at a time (16 MiB of records at most).
SPHERE_GROUP = 4096
#: Node rows this close are read together (one read, the rows between discarded).
NODE_GAP = 8


class LazyLod:
    """A ``.lod.ply`` opened by its header: ``offsets``, ``branching``, ``levels``,
    :attr:`cut_data` (whose arrays read on demand), :meth:`cut`, :meth:`nodes`."""

    def __init__(self, path: str | Path):
        self.path = Path(path)
        self.bytes_read = 0
        try:
            with open(self.path, "rb") as fh:
                header = ply.parse_header(self.path, fh)
                fh.seek(0)
                head = fh.read(header.body_offset)
        except OSError as exc:
            raise SceneFormatError(self.path, f"cannot read: {exc.strerror or exc}") from None
        self.bytes_read += len(head)
        self.branching = stored_branching(self.path, head)
        if header.order is None:
            raise SceneFormatError(self.path, "not a binary splatgl LOD file (an ASCII PLY); "
                                              "build one with 'splatgl lod'")
        anchor = stored_anchor(head)
        #: The leaves' 1-99 % box the header records ((lo, hi) float64), or None (written
        #: before it): what frames the file's views (:func:`splatgl.lod.stream_frames.framing_scene`).
        self.box = header_box(head)
        self.elements = {}  # name -> (byte offset, element)
        offset = header.body_offset
        for e in header.elements:
            self.elements[e.name] = (offset, e)
            offset += e.count * e.dtype(header.order).itemsize
        if BOUNDS not in self.elements or anchor is None:
            raise SceneFormatError(self.path, f"no '{BOUNDS}' element (written before lazy "
                                              "reading): build it again with 'splatgl lod'", BOUNDS)
        self.order = header.order
        n = self.elements["vertex"][1].count
        self.offsets = level_offsets(n, self.branching)
        if self.elements[BOUNDS][1].count != self.offsets[-1]:
            raise SceneFormatError(self.path, f"{self.elements[BOUNDS][1].count} spheres for "
                                              f"{self.offsets[-1]} nodes", BOUNDS)
        self.anchor = anchor
        self._fd = os.open(self.path, os.O_RDONLY)
        self._last_spheres: tuple | None = None   # (rows, centres, radii) of the last read
        self._mapped = None   # the file mapped read-only (_records), False: it cannot be
        self._recs: dict = {}   # element name -> its records in the mapping
        self.cut_data = CutData(_Centres(self), _Radius(self), self.offsets, self.branching,
                                self.anchor, dense=2.0)   # candidates only: see CutData

    @property
    def levels(self) -> int:
        return len(self.offsets) - 1

    def level_size(self, level: int) -> int:
        return int(self.offsets[level + 1] - self.offsets[level])

    def close(self) -> None:
        if self._mapped:
            self._mapped, self._recs = None, {}   # the mapping closes with its last array
        if self._fd is not None:
            os.close(self._fd)
            self._fd = None

    def __enter__(self) -> "LazyLod":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def _read(self, offset: int, size: int) -> bytes:
        parts, done = [], 0
        while done < size:
            chunk = os.pread(self._fd, size - done, offset + done)
            if not chunk:
                raise SceneFormatError(self.path, "file is truncated (or changed since it was opened)")
            parts.append(chunk)
            done += len(chunk)
        self.bytes_read += size
        return b"".join(parts)

    def _read_pages(self, pages: np.ndarray) -> np.ndarray:
        """The sphere records of ``pages`` (ascending, unique), page after page (the last
        page of the element may be short: its records are followed by zeros), consecutive
        pages read at once."""
        start, elem = self.elements[BOUNDS]
        dtype = elem.dtype(self.order)
        out = np.zeros(pages.size * BOUND_PAGE, dtype)
        cuts = np.concatenate([[0], np.flatnonzero(np.diff(pages) > 1) + 1, [pages.size]])
        for a, b in zip(cuts[:-1], cuts[1:]):
            lo = int(pages[a]) * BOUND_PAGE
            hi = min((int(pages[b - 1]) + 1) * BOUND_PAGE, elem.count)
            out[a * BOUND_PAGE:a * BOUND_PAGE + hi - lo] = np.frombuffer(
                self._read(start + lo * dtype.itemsize, (hi - lo) * dtype.itemsize), dtype)
        return out

    def spheres(self, rows) -> tuple[np.ndarray, np.ndarray]:
        """(centres (3, K) float32 relative to :attr:`anchor`, radii (K,)) of node ``rows``
        (an ascending index array or a slice), read from the file (its pages of BOUND_PAGE
        spheres, at most SPHERE_GROUP pages at a time) and not kept: a cut over a tree of any
        size holds only the spheres it is testing (the system's page cache keeps the file's)."""
        if isinstance(rows, slice):
            lo, hi, _ = rows.indices(int(self.offsets[-1]))
            rows = np.arange(lo, hi, dtype=np.int64)
        rows = np.asarray(rows, np.int64)
        last = self._last_spheres
        if last is not None and last[0].size == rows.size and np.array_equal(last[0], rows):
            return last[1], last[2]   # the radii of the rows whose centres were just read
        centres = np.empty((3, rows.size), np.float32)
        radius = np.empty(rows.size, np.float32)
        mapped = self._records(BOUNDS)
        page = rows // BOUND_PAGE
        firsts = np.concatenate([[0], np.flatnonzero(np.diff(page)) + 1]) if rows.size else rows
        for g in range(0, firsts.size, SPHERE_GROUP):
            a = int(firsts[g])
            b = int(firsts[g + SPHERE_GROUP]) if g + SPHERE_GROUP < firsts.size else rows.size
            if mapped is not None:   # gathered from the mapped file (no read loop), its pages
                got = mapped[1][rows[a:b]]   # then dropped from this process's RSS
                self.bytes_read += got.nbytes
                _drop_pages(*mapped, int(rows[a]), int(rows[b - 1]) + 1)
            else:
                pages = page[firsts[g:g + SPHERE_GROUP]]
                recs = self._read_pages(pages)
                got = recs[np.searchsorted(pages, page[a:b]) * BOUND_PAGE + rows[a:b] % BOUND_PAGE]
            xyz = np.stack([got[c].astype(np.float32) for c in "xyz"]).astype(np.float64)
            centres[:, a:b] = (xyz - self.anchor[:, None]).astype(np.float32)
            radius[a:b] = got["radius"]
        self._last_spheres = (rows, centres, radius)
        return centres, radius

    def _records(self, name: str):
        """``(mmap, records)``: element ``name``'s records in the file mapped read-only (None
        where it cannot be mapped: then they are read)."""
        if self._mapped is None:
            try:
                self._mapped = mmap.mmap(self._fd, 0, access=mmap.ACCESS_READ)
            except (OSError, ValueError):
                self._mapped = False
        if not self._mapped:
            return None
        if name not in self._recs:
            start, elem = self.elements[name]
            self._recs[name] = np.frombuffer(self._mapped, elem.dtype(self.order), elem.count, start)
        return self._mapped, self._recs[name]

    def sphere_columns(self):
        """``(x, y, z, radius, anchor)`` of every node's sphere, straight from the file's
        mapping (what the compiled cut reads: only the pages it touches come in, and
        :meth:`drop_sphere_pages` lets them go; :attr:`bytes_read` counts 16 bytes a sphere
        tested, as a gather does), or None (see :meth:`_Centres.columns`)."""
        mapped = self._records(BOUNDS)
        if mapped is None:
            return None
        recs = mapped[1]
        if recs.dtype.itemsize != 16 or any(recs.dtype[c] != np.dtype("<f4")
                                            for c in ("x", "y", "z", "radius")):
            return None
        flat = recs.view(np.float32).reshape(-1, 4)
        cols = [flat[:, recs.dtype.fields[c][1] // 4] for c in ("x", "y", "z", "radius")]
        return (*cols, np.array(self.anchor))   # writable: the type warm_up compiled

    def drop_sphere_pages(self, lo: int = 0, hi: int | None = None) -> None:
        """Let the mapped sphere pages of node rows ``lo:hi`` (default: all) leave this
        process's resident set (the system's page cache keeps them)."""
        mapped = self._records(BOUNDS) if self._mapped else None
        if mapped is not None and mapped[1].size:
            hi = mapped[1].size if hi is None else min(int(hi), mapped[1].size)
            if hi > lo:
                _drop_pages(*mapped, int(lo), hi)

    @property
    def sphere_bytes(self) -> int:
        """Bytes of node spheres kept between cuts: none (they are read as a cut tests them)."""
        return 0

    def trim_spheres(self, limit: int) -> bool:
        """Forget the spheres of the last read (kept for its radii); False: nothing more is
        kept (see :meth:`spheres`)."""
        self._last_spheres = None
        return False

    def nodes(self, rows: np.ndarray) -> Scene:
        """The stored values of node ``rows`` (ascending) as a :class:`Scene`, read in runs of
        rows at most NODE_GAP apart (leaves from ``vertex``, parents from ``lod_node``)."""
        rows = np.asarray(rows, np.int64)
        n = int(self.offsets[1])
        parts = []
        for name, sel, base in (("vertex", rows[rows < n], 0), (ELEMENT, rows[rows >= n], n)):
            if not sel.size:
                continue
            start, elem = self.elements[name]
            dtype = elem.dtype(self.order)
            local = sel - base
            mapped = self._records(name)
            if mapped is not None:   # gathered from the mapped file, its pages then dropped
                recs = mapped[1][local]
                self.bytes_read += recs.nbytes
                _drop_pages(*mapped, int(local[0]), int(local[-1]) + 1)
            else:
                got = []
                cuts = np.concatenate([[0], np.flatnonzero(np.diff(local) > NODE_GAP) + 1,
                                       [local.size]])
                for a, b in zip(cuts[:-1], cuts[1:]):  # runs of near rows, one read each
                    lo, hi = int(local[a]), int(local[b - 1]) + 1
                    run = np.frombuffer(self._read(start + lo * dtype.itemsize,
                                                   (hi - lo) * dtype.itemsize), dtype)
                    got.append(run[local[a:b] - lo])
                recs = np.concatenate(got)
            cols = ply._Columns(self.path, [p for p, _ in elem.properties], recs.shape[0])
            cols.fill(recs, 0)
            parts.append(activate(self.path, cols.means, cols.quats, cols.log_scales,
                                  cols.opacity, cols.sh))
        if len(parts) == 1:
            return parts[0]
        return Scene(*(np.concatenate([getattr(s, f) for s in parts])
                       for f in ("means", "quats", "log_scales", "opacity_logits", "sh")))

    def cut(self, camera: Camera, lod: LodSettings = LodSettings()):
        """``(rows, weights)`` of the cut for ``camera`` (:func:`select_cut_weights`, or the
        budget's search), reading only the spheres it tests."""
        if lod.budget is not None:
            rows, weights, _ = select_cut_budget(self.cut_data, camera, lod.budget,
                                                 lod.threshold_px, lod.band)
            return rows, weights
        return select_cut_weights(self.cut_data, camera, lod.threshold_px, lod.band)

    def cut_scene(self, camera: Camera, lod: LodSettings = LodSettings()) -> Scene:
        """The cut's nodes as a plain :class:`Scene`, each opacity ``o`` drawn with its weight
        ``w`` as ``1 - (1 - o) ** w`` (:func:`splatgl.lod.selection.blended_scene`'s twin)."""
        rows, weights = self.cut(camera, lod)
        sub = self.nodes(rows)
        if weights is None:
            return sub
        o = 1.0 - (1.0 - sub.opacities.astype(np.float64)) ** weights.astype(np.float64)
        return Scene.from_activated(sub.means, sub.quats, sub.scales, o, sub.sh, sub.kind)


def _drop_pages(mm, recs: np.ndarray, lo: int, hi: int) -> None:
    """Let the mapped records ``lo:hi`` of ``recs`` (an element in ``mm``) leave the process's
    resident pages (they stay in the system's page cache: a gather of any size holds only
    what it copied)."""
    if not hasattr(mm, "madvise"):
        return
    first = recs.ctypes.data - np.frombuffer(mm, np.uint8).ctypes.data + lo * recs.itemsize
    start = first // mmap.PAGESIZE * mmap.PAGESIZE
    end = min(len(mm), first + (hi - lo) * recs.itemsize)
    mm.madvise(mmap.MADV_DONTNEED, start, end - start)


class _Centres:
    """``centres[:, rows]`` (rows: an index array or a slice) of a :class:`LazyLod`'s nodes,
    read on demand."""

    def __init__(self, lod: LazyLod):
        self.lod = lod
        self.shape = (3, int(lod.offsets[-1]))

    def __getitem__(self, key):
        if isinstance(key, tuple) and len(key) == 2 and key[0] == slice(None):
            return self.lod.spheres(key[1])[0]
        raise TypeError(f"lazy centres take [:, rows], not {key!r}")

    def columns(self):
        """:meth:`splatgl.lod.cut.CutData.columns` of the file: its mapped spheres' ``x, y,
        z, radius`` (read-only float32 views, stored positions) and the anchor; None where
        the file cannot be mapped or its spheres are not little-endian float32."""
        return self.lod.sphere_columns()

    #: Rows of the compiled cut's slices: at most this span of spheres (64 MiB) is mapped in
    #: at once, however widely a level's candidates spread over the file.
    slice_rows = 1 << 22

    def release(self, lo: int, hi: int, tested: int) -> None:
        self.lod.bytes_read += 16 * tested   # as a gather of their spheres counts them
        self.lod.drop_sphere_pages(lo, hi)


class _Radius:
    def __init__(self, lod: LazyLod):
        self.lod = lod
        self.shape = (int(lod.offsets[-1]),)

    def __getitem__(self, key):
        return self.lod.spheres(key)[1]
