"""Streaming a level of detail from disk (issue 41 item 3): the resident set of node chunks.

A :class:`~splatgl.lod.lazy.LazyLod`'s node rows are cut into chunks of :data:`CHUNK_ROWS`
consecutive rows (levels are stored in Morton order, so a chunk is a compact patch of one
level).  :class:`ResidentSet` holds decoded chunks under a byte budget: loads run on a small
pool of background threads, the bytes of loads in flight are reserved before they start, and
the least recently used chunks are evicted to make room, so the chunks held plus those being
read never exceed the budget (:attr:`ResidentSet.peak_bytes` records the most it held).

Two ways to draw a cut (node rows and opacity weights, :mod:`splatgl.lod.cut`):

- :meth:`ResidentSet.gather` waits for every chunk the cut needs and returns its nodes as one
  :class:`~splatgl.scene.splats.Scene`, exact (path and screenshot frames, ``render``, ``eval``,
  ``bench``).  Chunks are copied out as they arrive, so a cut larger than the budget is still
  drawn: only the budget's worth stays resident.
- :meth:`ResidentSet.resident_cut` never waits (the viewer): a node whose chunk is not in yet
  is drawn as its nearest resident ancestor (the coarser node standing for it, its weight the
  sum of those it stands in for, at most 1), the missing chunks are requested, and
  ``on_loaded`` is called as each arrives (the viewer redraws).  Once every chunk is in, the
  cut is the exact one.  The chunks of the top :data:`PINNED_LEVELS` levels are loaded first
  (whole) and never evicted, so some ancestor is there; a node with none resident yet is
  not drawn.

:meth:`ResidentSet.close` stops the loaders promptly (Ctrl-C: loads not started are cancelled).
"""

from __future__ import annotations

import threading
from collections import OrderedDict
from concurrent.futures import CancelledError, Future, ThreadPoolExecutor
from dataclasses import dataclass

import numpy as np

from ..errors import SplatglError
from ..scene.splats import Scene
from .budget import format_size
from .stream_gather import FIELDS as _FIELDS, gather

#: Node rows per chunk (a few MiB of decoded SH3 rows).
CHUNK_ROWS = 4096
#: Loader threads.
LOADERS = 2
#: The chunks of this many levels from the top are loaded first and never evicted.
PINNED_LEVELS = 2


def concatenate(parts: list[Scene]) -> Scene:
    """The scenes ``parts`` one after the other."""
    if len(parts) == 1:
        return parts[0]
    return Scene(*(np.concatenate([getattr(s, f) for s in parts]) for f in _FIELDS), parts[0].kind)


def scene_bytes(scene: Scene) -> int:
    """Bytes of a scene's stored arrays."""
    return int(sum(getattr(scene, f).nbytes for f in _FIELDS))


class LazyChunks:
    """Chunks of a :class:`~splatgl.lod.lazy.LazyLod`'s node rows: ``count`` chunks of
    ``rows`` rows; :meth:`load` reads one (thread-safe: the reader uses ``pread``)."""

    def __init__(self, lazy, rows: int = CHUNK_ROWS):
        if rows < 1:
            raise SplatglError(f"chunk rows must be at least 1, got {rows}")
        self.lazy, self.rows = lazy, int(rows)
        self.nodes = int(lazy.offsets[-1])
        self.count = -(-self.nodes // self.rows)
        self.row_bytes = scene_bytes(lazy.nodes(np.zeros(1, np.int64)))  # decoded bytes a row

    def span(self, chunk: int) -> tuple[int, int]:
        lo = chunk * self.rows
        return lo, min(lo + self.rows, self.nodes)

    def estimate(self, chunk: int) -> int:
        lo, hi = self.span(chunk)
        return (hi - lo) * self.row_bytes

    def load(self, chunk: int) -> Scene:
        lo, hi = self.span(chunk)
        return self.lazy.nodes(np.arange(lo, hi, dtype=np.int64))

    def read_rows(self, rows: np.ndarray) -> Scene:
        """Node ``rows`` (ascending) alone, read in runs (thread-safe)."""
        return self.lazy.nodes(np.asarray(rows, np.int64))


@dataclass
class StreamStats:
    """What a :class:`ResidentSet` did: bytes held now and at most, chunks loaded and evicted."""

    resident_bytes: int = 0
    peak_bytes: int = 0
    loaded: int = 0
    evicted: int = 0
    resident_chunks: int = 0
    rows_read: int = 0   # rows of chunks read alone by gathers (SPARSE_CHUNK), not kept

    def summary(self, budget: int) -> str:
        alone = f", {self.rows_read:,} rows read alone" if self.rows_read else ""
        return (f"resident {format_size(self.resident_bytes)} (peak {format_size(self.peak_bytes)}"
                f" of {format_size(budget)}), chunks {self.resident_chunks} resident, "
                f"{self.loaded} loaded, {self.evicted} evicted{alone}")


class ResidentSet:
    """Decoded chunks of ``chunks`` (a :class:`LazyChunks` or anything with ``count``,
    ``rows``, ``nodes``, ``estimate(c)``, ``load(c)``) held under ``budget`` bytes (see the
    module doc).  ``offsets`` and ``branching``: the tree's, for the ancestors; ``pinned``:
    chunks never evicted instead of the top levels' (:mod:`splatgl.lod.stream_levels`)."""

    def __init__(self, chunks, budget: int, offsets: np.ndarray, branching: int,
                 threads: int = LOADERS, on_loaded=None, pinned=None):
        self.chunks, self.budget = chunks, int(budget)
        self.offsets = None if offsets is None else np.asarray(offsets, np.int64)
        self.branching = int(branching)
        self.on_loaded = on_loaded
        self._held: OrderedDict[int, Scene] = OrderedDict()   # LRU first
        self._sizes: dict[int, int] = {}
        self._pending: dict[int, Future] = {}
        self._reserved = 0   # bytes held back for loads in flight
        self._lock = threading.Condition()
        self._stop = threading.Event()
        self._pool = ThreadPoolExecutor(max(1, threads), thread_name_prefix="splatgl-lod-load")
        self.stats = StreamStats()
        self._pinned = frozenset()   # no tree (chunks of a level): nothing pinned
        if self.offsets is not None:
            top = max(0, len(self.offsets) - 1 - PINNED_LEVELS)
            self._pinned = frozenset(range(int(self.offsets[top]) // chunks.rows, chunks.count))
        if pinned is not None:   # chosen by the caller (a chunked level's coarsest chunks)
            self._pinned = frozenset(int(c) for c in pinned)
        largest = max((chunks.estimate(c) for c in range(chunks.count)), default=0)
        need = sum(chunks.estimate(c) for c in self._pinned) + largest * max(1, threads)
        self._room = self.budget - need   # for chunks besides the pinned, loads in flight
        if need > self.budget:
            raise SplatglError(f"--memory {format_size(self.budget)} is too small to stream this "
                               f"level of detail: its top levels and {max(1, threads)} chunks "
                               f"in flight need {format_size(need)}")

    # ------------------------------------------------------------------ loading and eviction
    def _evict_for(self, size: int, keep: frozenset | set = frozenset()) -> bool:
        """Evict least recently used chunks (not pinned, not in ``keep``) until ``size`` more
        bytes fit; False when they cannot.  Holds the lock."""
        held = self.stats.resident_bytes + self._reserved
        if held + size <= self.budget:
            return True
        for c in list(self._held):
            if c in self._pinned or c in keep:
                continue
            del self._held[c]
            freed = self._sizes.pop(c)
            self.stats.resident_bytes -= freed
            self.stats.evicted += 1
            held -= freed
            if held + size <= self.budget:
                break
        self.stats.resident_chunks = len(self._held)
        return held + size <= self.budget

    def _load(self, chunk: int, size: int) -> Scene | None:
        if self._stop.is_set():
            with self._lock:
                self._reserved -= size
                self._pending.pop(chunk, None)
                self._lock.notify_all()
            return None
        try:
            scene = self.chunks.load(chunk)
        except BaseException:
            with self._lock:
                self._reserved -= size
                self._pending.pop(chunk, None)
                self._lock.notify_all()
            raise
        with self._lock:
            self._reserved -= size
            self._pending.pop(chunk, None)
            self.stats.loaded += 1
            actual = scene_bytes(scene)
            if self._evict_for(actual):
                self._held[chunk] = scene
                self._sizes[chunk] = actual
                self.stats.resident_bytes += actual
                self.stats.peak_bytes = max(self.stats.peak_bytes, self.stats.resident_bytes
                                            + self._reserved)
            else:   # no room (a frame being gathered holds the rest): used once, not kept
                self.stats.evicted += 1
            self.stats.resident_chunks = len(self._held)
            self._lock.notify_all()
        if self.on_loaded is not None and not self._stop.is_set():
            self.on_loaded()
        return scene

    def request(self, chunks, keep: frozenset | set = frozenset()) -> dict[int, Future]:
        """Start loading those of ``chunks`` (in order of priority) neither held nor in flight,
        as far as the budget allows after evicting chunks not in ``keep``; returns the loads
        in flight for ``chunks``."""
        out = {}
        with self._lock:
            for c in chunks:
                c = int(c)
                if c in self._held:
                    continue
                fut = self._pending.get(c)
                if fut is None:
                    if self._stop.is_set():
                        break
                    size = self.chunks.estimate(c)
                    if not self._evict_for(size, keep):
                        break   # the rest waits for room
                    self._reserved += size
                    self.stats.peak_bytes = max(self.stats.peak_bytes,
                                                self.stats.resident_bytes + self._reserved)
                    fut = self._pool.submit(self._load, c, size)
                    self._pending[c] = fut
                out[c] = fut
        return out

    def held(self, chunk: int) -> Scene | None:
        """The chunk if resident (marked as just used), else None."""
        with self._lock:
            scene = self._held.get(chunk)
            if scene is not None:
                self._held.move_to_end(chunk)
            return scene

    def chunk_of(self, rows: np.ndarray) -> np.ndarray:
        return np.asarray(rows, np.int64) // self.chunks.rows

    def load_pinned(self) -> None:
        """Load the top levels' chunks (pinned) whole, kept, and wait for them (a gather read a
        chunk of few rows alone, not kept: the 100M scene's last chunk, 346 rows)."""
        self.collect(sorted(self._pinned), lambda c, scene: None)

    def fits(self, rows: np.ndarray) -> bool:
        """Whether the chunks of the cut ``rows`` can all be resident at once (besides the
        pinned ones and the loads in flight); else :meth:`resident_cut` never completes."""
        ids = [c for c in np.unique(self.chunk_of(rows)).tolist() if c not in self._pinned]
        return sum(self.chunks.estimate(c) for c in ids) <= self._room

    # ------------------------------------------------------------------------- the two draws
    def gather(self, rows: np.ndarray, cancelled=None) -> Scene:
        """The nodes ``rows`` (ascending) as one scene, waiting for their chunks (exact):
        :func:`splatgl.lod.stream_gather.gather` (held once; sparse chunks read row by row;
        ``cancelled()`` true: abandoned, :class:`~.stream_gather.Cancelled`)."""
        return gather(self, rows, cancelled)

    def read_alone(self, rows: np.ndarray) -> Future:
        """Node ``rows`` read alone on a loader thread (``chunks.read_rows``), not kept."""
        if self._stop.is_set():
            raise KeyboardInterrupt
        return self._pool.submit(self.chunks.read_rows, rows)

    def collect(self, need: list[int], take) -> dict:
        """``{chunk: take(chunk, its scene)}`` for the chunks ``need``, waiting for those not
        resident; each is taken as it arrives (a chunk with no room is used once, not kept)."""
        parts: dict = {}
        todo = list(need)
        while todo:
            for c in todo:
                scene = self.held(c)
                if scene is not None:
                    parts[c] = take(c, scene)
            todo = [c for c in todo if c not in parts]
            if not todo:
                break
            futures = self.request(todo)
            if not futures:   # nothing in flight and no room: wait for room, or fail
                if self._stop.is_set():
                    raise KeyboardInterrupt
                with self._lock:   # others' loads (the viewer's) hold the room: wait for them
                    busy = self._reserved > 0 and (self._lock.wait(0.05) or True)
                if busy:
                    continue
                raise SplatglError(f"--memory {format_size(self.budget)}: no room to load a "
                                   f"chunk of {format_size(self.chunks.estimate(todo[0]))}")
            for c, fut in futures.items():
                try:
                    scene = fut.result()
                except CancelledError:
                    raise KeyboardInterrupt from None
                if scene is None:
                    raise KeyboardInterrupt
                parts[c] = take(c, scene)
            todo = [c for c in todo if c not in parts]
        return parts

    def resident_cut(self, rows: np.ndarray, weights: np.ndarray | None, request: bool = True
                     ) -> tuple[np.ndarray, np.ndarray | None, bool]:
        """The cut ``(rows, weights)`` drawn from what is resident now, without waiting:
        ``(rows, weights, complete)`` (see the module doc); requests the missing chunks
        (``request``: not while a gather of the cut loads them)."""
        rows = np.asarray(rows, np.int64)
        with self._lock:
            present = np.zeros(self.chunks.count, bool)
            present[list(self._held)] = True
            for c in np.unique(self.chunk_of(rows)).tolist():
                if present[c]:
                    self._held.move_to_end(c)
        have = present[self.chunk_of(rows)]
        if have.all():
            return rows, weights, True
        w = np.ones(rows.size, np.float32) if weights is None else weights.astype(np.float32)
        out = rows.copy()
        todo = ~have
        offsets, b = self.offsets, self.branching
        level = np.searchsorted(offsets, out, side="right") - 1
        drawn = np.ones(rows.size, bool)
        while todo.any():   # climb one level where the chunk is missing
            idx = np.flatnonzero(todo)
            lv = level[idx]
            top = lv >= len(offsets) - 2
            if top.any():   # no ancestor resident (the pinned levels not in yet): not drawn
                drawn[idx[top]] = todo[idx[top]] = False
                idx, lv = idx[~top], lv[~top]
            local = (out[idx] - offsets[lv]) // b
            out[idx] = offsets[lv + 1] + local
            level[idx] = lv + 1
            todo[idx] = ~present[self.chunk_of(out[idx])]
        uniq, inv = np.unique(out[drawn], return_inverse=True)
        w = w[drawn]
        # The missing chunks, coarse first (the upper levels' before the leaves'); only the
        # cut's resident chunks are kept: the others (stand-ins among them) may make room.
        # With every resident chunk kept, a full budget never refined a new view.
        if request:
            self.request(np.unique(self.chunk_of(rows[~have]))[::-1],
                         keep=frozenset(np.unique(self.chunk_of(rows[have])).tolist()))
        wsum = np.minimum(np.bincount(inv, weights=w.astype(np.float64)), 1.0).astype(np.float32)
        return uniq, (None if weights is None and wsum.size == uniq.size and (wsum >= 1).all()
                      else wsum), False

    def close(self) -> None:
        """Stop the loaders: loads not started are cancelled, the one running finishes."""
        self._stop.set()
        self._pool.shutdown(wait=False, cancel_futures=True)
        with self._lock:
            for fut in self._pending.values():
                fut.cancel()
            self._lock.notify_all()

    def __enter__(self) -> "ResidentSet":
        return self

    def __exit__(self, *exc) -> None:
        self.close()
