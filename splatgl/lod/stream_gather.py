"""A streamed cut's nodes gathered into one scene (issue 41 item 3): what
:meth:`splatgl.lod.stream.ResidentSet.gather` does.

The scene's arrays are allocated once, at the cut's size, and each chunk's rows are copied in as
it arrives (no per-chunk copies to concatenate: the cut is held once).  A chunk the cut needs
fewer than SPARSE_CHUNK of the rows of, and that is not resident, is not loaded whole: its rows
are read alone (several chunks' at a time, SPARSE_BATCH rows a read, on the loader threads) and
not kept.  A cut mixing levels touches many chunks for a few rows each (the 20M tiled scene's
capped default view: 4.2M nodes over 26.6M chunk rows).
"""

from __future__ import annotations

from concurrent.futures import CancelledError, Future

import numpy as np

from ..scene.splats import Scene

#: The stored arrays of a scene, in :class:`~splatgl.scene.splats.Scene`'s order.
FIELDS = ("means", "quats", "log_scales", "opacity_logits", "sh")
#: Below this fraction of a chunk's rows, a gather reads the rows alone.
SPARSE_CHUNK = 0.25
#: Rows read alone at a time: a read maps at most that many file pages before it drops them
#: (1 << 15 raised the 100M far view's peak by 500 MB with four reads in flight).
SPARSE_BATCH = 1 << 13
#: Reads of rows alone in flight at once.
WINDOW = 4


class Cancelled(Exception):
    """A gather abandoned (its ``cancelled()`` became true: the viewer wants another cut)."""


def gather(resident, rows: np.ndarray, cancelled=None) -> Scene:
    """The nodes ``rows`` (ascending) of ``resident`` (a
    :class:`~splatgl.lod.stream.ResidentSet`) as one scene, waiting for their chunks (exact);
    raises :class:`Cancelled` as a chunk arrives once ``cancelled()`` is true."""
    rows = np.asarray(rows, np.int64)
    per = resident.chunks.rows
    ids = resident.chunk_of(rows)
    need = np.unique(ids)
    cuts = np.searchsorted(ids, need)
    bounds = dict(zip(need.tolist(), zip(cuts.tolist(), np.append(cuts[1:], rows.size).tolist())))
    out: dict = {}

    def take(c: int, scene: Scene, start: int | None = None) -> bool:
        if cancelled is not None and cancelled():
            raise Cancelled
        a, b = bounds[c]   # the chunk's rows, or (start) rows start.. of rows read alone
        local = rows[a:b] - c * per if start is None else np.arange(start, start + b - a)
        if not out:   # the arrays, at the cut's size, from the first chunk's shapes
            out.update({f: np.empty((rows.size,) + getattr(scene, f).shape[1:], np.float32)
                        for f in FIELDS}, kind=scene.kind)
        for f in FIELDS:
            np.take(getattr(scene, f), local, axis=0, out=out[f][a:b], mode="clip")
        return True

    sparse = [] if getattr(resident.chunks, "read_rows", None) is None else [
        c for c in need.tolist()
        if bounds[c][1] - bounds[c][0] < SPARSE_CHUNK * per and resident.held(c) is None]
    alone = set(sparse)
    resident.collect([c for c in need.tolist() if c not in alone], take)
    _read_alone(resident, sparse, rows, bounds, take)
    if not out:
        return resident.chunks.load(0).subset(rows[:0])
    for f in FIELDS:
        out[f].flags.writeable = False   # adopted by the Scene as they are (no copy)
    return Scene(*(out[f] for f in FIELDS), out["kind"])


def _read_alone(resident, chunks: list[int], rows: np.ndarray, bounds: dict, take) -> None:
    """``take(chunk, scene, start)`` of each of ``chunks``' rows of ``rows``
    (``rows[bounds[chunk]]``, at ``start`` in ``scene``), read alone SPARSE_BATCH rows at a time
    (several chunks a read, WINDOW reads in flight, each copied out as it comes), none kept."""
    groups, group, count = [], [], 0
    for c in chunks:
        group.append(c)
        count += bounds[c][1] - bounds[c][0]
        if count >= SPARSE_BATCH:
            groups.append(group)
            group, count = [], 0
    if group:
        groups.append(group)
    pending: dict[Future, list[int]] = {}
    while groups or pending:
        while groups and len(pending) < WINDOW:
            g = groups.pop(0)
            pending[resident.read_alone(np.concatenate([rows[slice(*bounds[c])] for c in g]))] = g
        fut = next(iter(pending))
        g = pending.pop(fut)
        try:
            scene = fut.result()
        except CancelledError:
            raise KeyboardInterrupt from None
        resident.stats.rows_read += scene.count
        start = 0
        for c in g:
            take(c, scene, start)
            start += bounds[c][1] - bounds[c][0]
