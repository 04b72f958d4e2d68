"""``--remove-floaters`` and ``--decimate`` on scenes larger than ``--memory`` (issue 41 item 5):
per spatial chunk, the splats sorted on disk in the Morton order of their 1-99 % box
(:mod:`.streamed_sort`), so a chunk is a run of consecutive codes; each splat is decided by the
one chunk that owns it.

**Floaters** (:func:`find_floaters`): each chunk's k-d tree holds its own centres and a *halo*:
the centres of the other chunks within ``r`` of its bounding box, ``r`` the 99th percentile of
its splats' k-th neighbour distance among themselves.  A splat whose k-th neighbour in that
tree lies within ``r`` has its exact neighbours (every centre left out is farther than ``r``);
the others (isolated splats: the floaters among them) are queried against every chunk whose
box is nearer than their k-th neighbour so far, merging the nearest: their distances are exact
too.  The mean and standard deviation of the distances are sums of per-chunk sums, so the
threshold can differ from the in-memory one in its last bits, and a splat whose distance lies
within that rounding of the threshold could be decided differently: the set removed is
otherwise the in-memory set (docs/editing.md gives the measurements).

**Decimate** (:func:`decimate_chunks`): each chunk of consecutive Morton codes is decimated
alone (:meth:`Decimate.apply`) to its share of the target (the target times the chunk's share
of the splats, rounded so the shares sum to the target; a chunk holds at least half a sorted
run and takes consecutive runs until its share is a splat or more): the count is the in-memory
count, but
no pair crosses a chunk boundary and the cheapest pairs are chosen per chunk, not over the
scene, so the result differs from the in-memory decimation (measured as image PSNR, said once
in the command's output).  The merged rows come chunk by chunk, in Morton order.
"""

from __future__ import annotations

import math

import numpy as np

from ..lod.ply_rows import BoxFinder
from ..scene.spatial import morton_codes_clamped
from .decimate import Decimate
from .floaters import Floaters, RemoveFloaters
from .streamed_sort import sorted_runs, to_records, to_scene

#: The note the command prints once for a chunked decimation.
DECIMATE_NOTE = ("--decimate over --memory merges within spatial chunks of about {rows:,} "
                 "splats (no pair crosses a chunk; the count is exact, the splats merged differ "
                 "from the in-memory decimation's: docs/editing.md)")
#: The share of a chunk's splats whose neighbours its halo is sized for.
HALO_QUANTILE = 0.99
POINT = np.dtype([("code", "<u8"), ("index", "<i8"), ("means", "<f4", 3), ("opacity", "<f8")])


def _box(points) -> tuple[np.ndarray, np.ndarray, int]:
    """The exact 1-99 % box of the centres ``points()`` yields (two passes) and their count."""
    n = sum(m.shape[0] for m in points())
    box = BoxFinder(max(n, 1))
    for m in points():
        box.add_first(m)
    for m in points():
        box.add_second(m)
    lo, hi = box.box()
    return lo, hi, n


def find_floaters(op: RemoveFloaters, kept, folder, run: int):
    """The input rows ``op`` removes and its :class:`Floaters` statistics (its mask empty):
    ``kept()`` yields ``(index, means, opacity)`` of the splats left before it, block by block
    (see the module notes)."""
    lo, hi, n = _box(lambda: (m for _, m, _ in kept()))
    k = op.neighbours
    if n <= k:
        return np.zeros(0, np.int64), Floaters(op, np.zeros(n, bool), 0.0, 0.0, math.inf)
    recs = (np.rec.fromarrays([morton_codes_clamped(m.astype(np.float64), lo, hi), i, m, o],
                              dtype=POINT) for i, m, o in kept())
    chunks = []  # (file, lo, hi) per chunk
    for c, data in enumerate(sorted_runs(folder, POINT, recs, run, run)):
        path = folder / f"chunk{c}"
        np.ascontiguousarray(data).tofile(path)
        chunks.append((path, data["means"].min(axis=0).astype(np.float64),
                       data["means"].max(axis=0).astype(np.float64)))
    dist_path = folder / "distances"
    sums, unsure = [], []
    with open(dist_path, "wb") as out:
        for c, (path, blo, bhi) in enumerate(chunks):
            own = np.fromfile(path, POINT)
            d, sure = _chunk_distances(own, c, chunks, k)
            unsure += [int((~sure).sum())]
            d[~sure] = _exact_distances(own["means"][~sure], chunks, k)
            sums.append(float(d.sum()))
            np.rec.fromarrays([own["index"], d, own["opacity"]],
                              names="index,d,opacity").tofile(out)
    table = np.dtype([("index", "<i8"), ("d", "<f8"), ("opacity", "<f8")])
    mean = math.fsum(sums) / n
    squares = math.fsum(float(((b["d"] - mean) ** 2).sum()) for b in _file_blocks(dist_path, table,
                                                                                  run))
    sd = math.sqrt(squares / n)
    threshold = mean + op.sigma * sd
    removed = [b["index"][(b["d"] > threshold) & (b["opacity"] < op.opacity)]
               for b in _file_blocks(dist_path, table, run)]
    return (np.sort(np.concatenate(removed)),
            Floaters(op, np.zeros(0, bool), mean, sd, threshold))


def _file_blocks(path, dtype, rows: int):
    with open(path, "rb") as fh:
        while True:
            block = np.fromfile(fh, dtype, rows)
            if not block.size:
                return
            yield block


def _chunk_distances(own, c: int, chunks, k: int):
    """(mean distance to the k nearest other centres, whether it is exact) of chunk ``c``'s
    splats, from a tree of the chunk and its halo."""
    from scipy.spatial import cKDTree

    means = own["means"]
    inner = cKDTree(means.astype(np.float64))
    kth = inner.query(means, k=min(k + 1, len(means)), workers=-1)[0]
    kth = kth[:, -1] if kth.ndim == 2 and len(means) > k else np.full(len(means), np.inf)
    finite = kth[np.isfinite(kth)]
    r = float(np.quantile(finite, HALO_QUANTILE)) if finite.size else 0.0
    _, blo, bhi = chunks[c]
    halo = [means]
    for j, (path, lo, hi) in enumerate(chunks):
        if j == c or (lo > bhi + r).any() or (hi < blo - r).any():
            continue
        other = np.fromfile(path, POINT)["means"]
        near = ((other >= blo - r) & (other <= bhi + r)).all(axis=1)
        halo.append(other[near])
    points = np.concatenate(halo)
    tree = cKDTree(points.astype(np.float64), balanced_tree=False, compact_nodes=False)
    if points.shape[0] <= k:
        return np.zeros(len(means)), np.zeros(len(means), bool)
    d, _ = tree.query(means, k=k + 1, workers=-1)
    return d[:, 1:].mean(axis=1), d[:, k] <= r


def _exact_distances(means, chunks, k: int) -> np.ndarray:
    """The mean distance to the k nearest other centres over every chunk (the nearest merged
    chunk by chunk, chunks farther than the k-th so far skipped)."""
    from scipy.spatial import cKDTree

    best = np.full((means.shape[0], k + 1), np.inf)
    if not means.shape[0]:
        return np.zeros(0)
    q = means.astype(np.float64)
    for path, lo, hi in chunks:
        gap = np.sqrt((np.maximum(np.maximum(lo - q, q - hi), 0.0) ** 2).sum(axis=1))
        rows = np.flatnonzero(gap <= best[:, k])
        if not rows.size:
            continue
        pts = np.fromfile(path, POINT)["means"]
        m = min(k + 1, pts.shape[0])
        d, _ = cKDTree(pts.astype(np.float64)).query(means[rows], k=m, workers=-1)
        d = d.reshape(rows.size, m)
        best[rows] = np.sort(np.concatenate([best[rows], d], axis=1), axis=1)[:, :k + 1]
    return best[:, 1:].mean(axis=1)


def decimate_chunks(op: Decimate, blocks, kind, coeffs: int, total: int, folder, run: int):
    """The decimated Scenes of the splats ``blocks()`` yields (``total`` of them, ``coeffs``
    SH coefficients), chunk by chunk (see the module notes), and the target."""
    lo, hi, _ = _box(lambda: (b.means for b in blocks()))
    from .streamed_sort import record_dtype

    dtype = record_dtype(kind, coeffs)
    recs = (to_records(b, morton_codes_clamped(b.means.astype(np.float64), lo, hi), dtype)
            for b in blocks())
    target = op.target(total)
    done = cum = 0
    pending: list[np.ndarray] = []
    for data in sorted_runs(folder, dtype, recs, run, run):
        pending.append(data)
        cum += data.shape[0]
        held = sum(p.shape[0] for p in pending)
        t = min(held, int(round(cum * target / total)) - done)
        if held < run // 2 or t < 1:  # a chunk is at least half a run and merges to >= 1
            continue
        done += t
        yield Decimate(count=t).apply(to_scene(np.concatenate(pending), kind))
        pending = []
    if pending:  # the rest (its share rounded to none only after a chunk took it: one splat)
        held = sum(p.shape[0] for p in pending)
        yield Decimate(count=min(held, max(1, target - done))).apply(
            to_scene(np.concatenate(pending), kind))
