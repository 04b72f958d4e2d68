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
run and takes consecutive runs until its share, and what it leaves the rest, are a splat or
more; a target below the number of chunks is refused in one line, since chunks would then pile
up unmerged past the budget): the count is the in-memory count, but
no pair crosses a chunk boundary and the cheapest pairs are chosen per chunk, not over the
scene, so the result differs from the in-memory decimation (measured as image PSNR, said once
in the command's output).  The merged rows come chunk by chunk, in Morton order.
"""

from __future__ import annotations

import math
import re

import numpy as np

from ..errors import SplatglError
from ..lod.budget import RESERVE, resident_now
from ..lod.external import file_blocks
from ..lod.ply_rows import BoxFinder
from ..scene.spatial import morton_codes_clamped
from .decimate import Decimate, _check_scales, check_kind
from .floaters import Floaters, RemoveFloaters
from .streamed_sort import record_dtype, sorted_runs, to_records, to_scene

#: The note the command prints once for a chunked decimation.
DECIMATE_NOTE = ("--decimate over --memory merges within spatial chunks of about {rows:,} "
                 "splats (no pair crosses a chunk; the count is exact, the splats merged differ "
                 "from the in-memory decimation's: docs/editing.md)")
#: The share of a chunk's splats whose neighbours its halo is sized for.
HALO_QUANTILE = 0.99
#: Splats per k-d tree query (its float64 distances and indices).
QUERY_ROWS = 1 << 16
#: The most splats a floater chunk holds, however large the budget.
MAX_CHUNK = 1 << 22
POINT = np.dtype([("code", "<u8"), ("index", "<i8"), ("means", "<f4", 3), ("opacity", "<f8")])


def floater_rows(memory: int, k: int, rows: int, held: int | None = None) -> int:
    """Splats per floater chunk within ``memory`` bytes (``held``: what the process holds,
    measured when None): per splat its record and a halo's (a chunk's at most) with their
    tree, a query's k + 1 distances and indices, and a batch row of the unsure; at least
    ``rows`` (the edit's blocks)."""
    held = resident_now() if held is None else held
    working = memory - held - RESERVE
    per = 2 * POINT.itemsize + 120 + 8 * (k + 1) + 3 * (POINT.itemsize + 8 * (k + 1))
    return int(max(rows, min(working // per, MAX_CHUNK))) if working > 0 else rows


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
    ``kept()`` yields ``(index, means, opacity)`` of the splats left before it, block by block;
    chunks of at most ``run`` splats (see the module notes)."""
    lo, hi, n = _box(lambda: (m for _, m, _ in kept()))
    k = op.neighbours
    if n <= k:
        return np.zeros(0, np.int64), Floaters(op, np.zeros(n, bool), 0.0, 0.0, math.inf)
    recs = (np.rec.fromarrays([morton_codes_clamped(m.astype(np.float64), lo, hi), i, m, o],
                              dtype=POINT) for i, m, o in kept())
    chunks = []  # (file, lo, hi) per chunk
    for c, data in enumerate(sorted_runs(folder, POINT, recs, run, run, n)):
        path = folder / f"chunk{c}"
        np.ascontiguousarray(data).tofile(path)
        chunks.append((path, data["means"].min(axis=0).astype(np.float64),
                       data["means"].max(axis=0).astype(np.float64)))
    dist_path = folder / "distances"
    with open(dist_path, "wb") as out:
        unsure = _Unsure(chunks, k, run, out)
        for c, (path, _, _) in enumerate(chunks):
            own = np.fromfile(path, POINT)
            d, sure, box = _chunk_distances(own["means"], c, chunks, k, run)
            dist = d[sure, 1:].mean(axis=1)
            _table(own["index"][sure], dist, own["opacity"][sure]).tofile(out)
            unsure.sums.append(float(dist.sum()))
            points, rows = own[~sure], d[~sure]
            del own, d  # before a flush
            unsure.add(points, rows, c, box)
        unsure.flush()
    mean = math.fsum(unsure.sums) / n
    squares = math.fsum(float(((b["d"] - mean) ** 2).sum())
                        for b in file_blocks(dist_path, TABLE, run))
    sd = math.sqrt(squares / n)
    threshold = mean + op.sigma * sd
    removed = [b["index"][(b["d"] > threshold) & (b["opacity"] < op.opacity)]
               for b in file_blocks(dist_path, TABLE, run)]
    return (np.sort(np.concatenate(removed)),
            Floaters(op, np.zeros(0, bool), mean, sd, threshold))


TABLE = np.dtype([("index", "<i8"), ("d", "<f8"), ("opacity", "<f8")])


def _table(index, d, opacity) -> np.ndarray:
    out = np.empty(index.size, TABLE)
    out["index"], out["d"], out["opacity"] = index, d, opacity
    return out


def _chunk_distances(means, c: int, chunks, k: int, cap: int):
    """The (M, k+1) distances to the nearest centres of chunk ``c``'s splats in a tree of the
    chunk and its halo, which of them are exact, and the halo's box (empty where the halo
    would pass ``cap`` centres: none then)."""
    from scipy.spatial import cKDTree

    m = means.shape[0]
    kth = np.full(m, np.inf)
    if m > k:  # the k-th neighbour's distance only
        kth = cKDTree(means.astype(np.float64)).query(means, k=[k + 1], workers=-1)[0][:, 0]
    finite = kth[np.isfinite(kth)]
    r = float(np.quantile(finite, HALO_QUANTILE)) if finite.size else 0.0
    _, blo, bhi = chunks[c]
    box = (blo - r, bhi + r)
    halo, held = [means], 0
    for j, (path, lo, hi) in enumerate(chunks):
        if j == c or (lo > box[1]).any() or (hi < box[0]).any():
            continue
        other = np.fromfile(path, POINT)["means"]
        halo.append(other[_inside(other, box)])
        held += halo[-1].shape[0]
        if held > cap:  # a chunk spread over the scene (clamped outliers): no halo
            halo, r, box = [means], -1.0, (np.full(3, np.inf), np.full(3, -np.inf))
            break
    points = np.concatenate(halo)
    tree = cKDTree(points.astype(np.float64), balanced_tree=False, compact_nodes=False)
    del points, halo
    d = _query(tree, means, k)
    return d, d[:, k] <= r, box


def _query(tree, means, k: int) -> np.ndarray:
    """(M, k+1) distances to the nearest centres in ``tree`` (inf past its centres), a slice
    of QUERY_ROWS at a time (the neighbours' indices are not kept)."""
    q = min(k + 1, tree.n)
    d = np.full((means.shape[0], k + 1), np.inf)
    for s in range(0, means.shape[0], QUERY_ROWS):
        part = tree.query(means[s:s + QUERY_ROWS], k=q, workers=-1)[0]
        d[s:s + QUERY_ROWS, :q] = part.reshape(-1, q)
    return d


def _inside(points, box) -> np.ndarray:
    return ((points >= box[0]) & (points <= box[1])).all(axis=1)


class _Unsure:
    """Splats whose halo did not hold their k nearest neighbours for certain: queried against
    every chunk nearer than their k-th neighbour so far, the points their own tree held left
    out (their chunk's, and those inside their halo's box), a batch of at most ``run`` at a
    time; their mean distances go to ``out``.  ``sums``: every distance's sum, per batch and
    chunk."""

    def __init__(self, chunks, k: int, run: int, out):
        self.chunks, self.k, self.run, self.out = chunks, k, run, out
        self.parts: list[tuple] = []
        self.held = 0
        self.sums: list[float] = []
        self.boxes: dict[int, tuple] = {}

    def add(self, points, d, c: int, box) -> None:
        self.boxes[c] = box
        if points.size:
            self.parts.append((points, d, np.full(points.size, c)))
            self.held += points.size
        if self.held >= self.run // 2:
            self.flush()

    def flush(self) -> None:
        from scipy.spatial import cKDTree

        if not self.parts:
            return
        pts = np.concatenate([p[0] for p in self.parts])
        best = np.concatenate([p[1] for p in self.parts])
        owner = np.concatenate([p[2] for p in self.parts])
        self.parts, self.held = [], 0
        k = self.k
        for j, (path, lo, hi) in enumerate(self.chunks):
            near = np.zeros(pts.size, bool)
            for s in range(0, pts.size, QUERY_ROWS):  # the box's distance, a slice at a time
                q = pts["means"][s:s + QUERY_ROWS].astype(np.float64)
                gap = np.sqrt((np.maximum(np.maximum(lo - q, q - hi), 0.0) ** 2).sum(axis=1))
                near[s:s + QUERY_ROWS] = (gap <= best[s:s + QUERY_ROWS, k]) & \
                    (owner[s:s + QUERY_ROWS] != j)
            if not near.any():
                continue
            other = np.fromfile(path, POINT)["means"]
            for c in np.unique(owner[near]):
                group = np.flatnonzero(near & (owner == c))
                fresh = other[~_inside(other, self.boxes[int(c)])]
                if not fresh.shape[0]:
                    continue
                tree = cKDTree(fresh.astype(np.float64))
                for s in range(0, group.size, QUERY_ROWS):
                    rows = group[s:s + QUERY_ROWS]
                    d = np.concatenate([best[rows], _query(tree, pts["means"][rows], k)], axis=1)
                    best[rows] = np.sort(d, axis=1)[:, :k + 1]
        dist = best[:, 1:].mean(axis=1)
        _table(pts["index"], dist, pts["opacity"]).tofile(self.out)
        self.sums.append(float(dist.sum()))


def _checked(blocks):
    """``blocks`` with the decimation's scale check, naming the row in the whole scene."""
    first = 0
    for block in blocks:
        try:
            _check_scales(block)
        except SplatglError as exc:
            exc.args = (re.sub(r"splat ([\d,]+)", lambda m: "splat "
                               f"{first + int(m.group(1).replace(',', '')):,}", str(exc),
                               count=1),)
            raise
        first += block.count
        yield block


def decimate_chunks(op: Decimate, blocks, kind, coeffs: int, total: int, folder, run: int):
    """The decimated Scenes of the splats ``blocks()`` yields (``total`` of them, ``coeffs``
    SH coefficients), chunk by chunk (see the module notes), and the target."""
    check_kind(kind)
    target = op.target(total)
    chunks = -(-total // max(1, run))
    if 0 < target < chunks:   # a chunk's share under one splat: chunks would pile up unmerged
        raise SplatglError(f"--decimate {op.describe().split(' by ')[0]} over --memory leaves "
                           f"{target:,} splats, fewer than the {chunks:,} spatial chunks of about "
                           f"{run:,} splats it merges within (one splat each at least): ask for "
                           f"at least {chunks:,}, or give more --memory")
    lo, hi, _ = _box(lambda: (b.means for b in _checked(blocks())))

    dtype = record_dtype(kind, coeffs)
    recs = (to_records(b, morton_codes_clamped(b.means.astype(np.float64), lo, hi), dtype)
            for b in blocks())
    done = cum = 0
    pending: list[np.ndarray] = []
    for data in sorted_runs(folder, dtype, recs, run, run, total):
        pending.append(data)
        cum += data.shape[0]
        held = sum(p.shape[0] for p in pending)
        t = min(held, int(round(cum * target / total)) - done)
        if held < run // 2 or t < 1 or (cum < total and target - done - t < 1):
            continue  # a chunk: half a run or more, merged to >= 1, leaving the rest >= 1
        done += t
        yield Decimate(count=t).apply(to_scene(np.concatenate(pending), kind))
        pending = []
    if pending:  # the rest, its share at least one splat
        yield Decimate(count=target - done).apply(to_scene(np.concatenate(pending), kind))
