"""Which level each chunk of a Streamed SOG or LCC scene is drawn at (issue 41 items 3 and 4):
the chunked formats' counterpart of the ``.lod.ply`` cut (:mod:`splatgl.lod.cut`).

A chunk (a Streamed SOG tree leaf, an LCC grid unit) holds, per level, a stand-in for its region
of the scene.  A level's *world error* is the radius of the region each of its splats stands for:
the sphere of volume ``V / n`` (``V`` the chunk's box volume, each side at least
:data:`FLAT_SIDE` of its longest so a flat chunk keeps a volume; ``n`` its splats at that
level), 0 at the chunk's finest level, never smaller than a finer level's.  Its *screen error*
is that radius in pixels at the chunk's bounding sphere (the cut's node test,
:func:`sphere_sizes`: ``f e / (d - R)``, infinite inside the sphere).

:func:`choose_levels` draws each chunk at its coarsest level whose screen error is at most
``threshold_px`` (``--lod-threshold``; level 0 where the camera is inside the chunk's sphere);
with a splat budget (``--lod-budget``) chunks are then coarsened one level at a time, the one
whose next level's screen error is smallest first, until the splats fit (or every chunk is at
its coarsest).  Chunks whose sphere lies wholly outside the view are not drawn.  A level given
(``--lod-level N``) draws every chunk in view at that level.  Levels a chunk holds no splats at
are never chosen for it.  :func:`cap_levels` coarsens a choice alike under a streamed frame's
splat cap.  The files' own per-chunk ``errors`` are not read (PlayCanvas derives them as log
ratios of counts, not lengths).
"""

from __future__ import annotations

import heapq
from dataclasses import dataclass

import numpy as np

from ..cameras.camera import Camera
from .cut import CutData, _NodeTest
from .selection import LodSettings

#: A chunk box's side counts as at least this fraction of its longest (flat chunks).
FLAT_SIDE = 1e-2
#: Not drawn: the level of a chunk out of view (or holding no splats at the level given).
NOT_DRAWN = -1


def sphere_sizes(camera: Camera, anchor: np.ndarray, centres: np.ndarray,
                 radius: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(projected radius in px, touches the view) of spheres: ``centres`` (3, K) float32
    relative to ``anchor``, ``radius`` (K,), by the ``.lod.ply`` cut's own node test."""
    data = CutData(centres, radius, np.zeros(1, np.int64), 1, np.asarray(anchor, np.float64))
    return _NodeTest(data, camera).test(centres, radius)


def level_errors(lo: np.ndarray, hi: np.ndarray, counts: np.ndarray) -> np.ndarray:
    """(K, L) world error of each chunk's levels (see the module doc); inf where a chunk has
    no splats at a level."""
    extent = np.maximum(np.asarray(hi, np.float64) - lo, 0.0)
    longest = np.maximum(extent.max(1, initial=0.0), np.finfo(np.float32).tiny)
    volume = np.prod(np.maximum(extent, FLAT_SIDE * longest[:, None]), 1)
    n = np.asarray(counts, np.float64)
    present = n > 0
    with np.errstate(divide="ignore"):
        raw = np.where(present, np.cbrt(3.0 * volume[:, None] / (4.0 * np.pi * np.maximum(n, 1))),
                       np.nan)
    finest = np.argmax(present, 1)
    raw[np.arange(len(raw)), finest] = 0.0
    err = np.fmax.accumulate(raw, 1)   # never below a finer level's
    return np.where(present, err, np.inf)


@dataclass(frozen=True)
class ChunkTable:
    """The view-independent arrays of the choice: ``centres`` (3, K) float32 chunk box centres
    relative to ``anchor``, ``radius`` (K,) float32 half-diagonals, ``counts`` (K, L) splats
    per chunk and level, ``errors`` (K, L) world errors (:func:`level_errors`)."""

    centres: np.ndarray
    radius: np.ndarray
    counts: np.ndarray
    errors: np.ndarray
    anchor: np.ndarray

    @classmethod
    def of(cls, structure, anchor: np.ndarray) -> "ChunkTable":
        """From a structure of :func:`splatgl.formats.streamed_sog.read_structure` or
        :func:`splatgl.formats.lcc.read_structure`."""
        lo = np.array([c.bound_min for c in structure.chunks], np.float64).reshape(-1, 3)
        hi = np.array([c.bound_max for c in structure.chunks], np.float64).reshape(-1, 3)
        counts = np.array([[c.count(level) for level in range(structure.levels)]
                           for c in structure.chunks], np.int64).reshape(-1, structure.levels)
        anchor = np.asarray(anchor, np.float64)
        centres = np.ascontiguousarray((0.5 * (lo + hi) - anchor).T, np.float32)
        radius = (0.5 * np.linalg.norm(hi - lo, axis=1)).astype(np.float32)
        return cls(centres, radius, counts, level_errors(lo, hi, counts), anchor)

    @property
    def levels(self) -> int:
        return self.counts.shape[1]

    def splats(self, levels: np.ndarray) -> int:
        """Splats drawn by the choice ``levels`` (K,)."""
        drawn = levels >= 0
        return int(self.counts[np.flatnonzero(drawn), levels[drawn]].sum())


def screen_errors(table: ChunkTable, camera: Camera) -> tuple[np.ndarray, np.ndarray]:
    """((K, L) screen error in px of each chunk's levels, (K,) whether the chunk is in view)."""
    size, inside = sphere_sizes(camera, table.anchor, table.centres, table.radius)
    scale = size.astype(np.float64) / np.maximum(table.radius, np.finfo(np.float32).tiny)
    with np.errstate(invalid="ignore"):
        px = scale[:, None] * table.errors
    px[table.errors == 0.0] = 0.0   # the finest level (also inside the sphere: inf x 0)
    return px, np.asarray(inside, bool)


def choose_levels(table: ChunkTable, camera: Camera, lod: LodSettings = LodSettings(),
                  level: int | None = None) -> np.ndarray:
    """(K,) the level each chunk is drawn at for ``camera`` (:data:`NOT_DRAWN`: not drawn):
    ``level`` for every chunk in view, else by screen error under ``lod``'s threshold and
    budget (the module doc; ``lod.band`` is not read: a chunk switches levels whole)."""
    px, inside = screen_errors(table, camera)
    k = len(px)
    if level is not None:
        out = np.where(inside & (table.counts[:, level] > 0), level, NOT_DRAWN)
        return out.astype(np.int64)
    ok = px <= lod.threshold_px
    out = (table.levels - 1 - np.argmax(ok[:, ::-1], 1)).astype(np.int64)   # the coarsest ok
    out[~inside | (table.counts.sum(1) == 0)] = NOT_DRAWN
    if lod.budget is not None:
        _coarsen(table, px, out, lod.budget)
    return out if k else np.zeros(0, np.int64)


def cap_levels(table: ChunkTable, camera: Camera, levels: np.ndarray, cap: int) -> np.ndarray:
    """``levels`` coarsened as a budget of ``cap`` splats coarsens them (a streamed frame's
    memory bound, :func:`splatgl.lod.budget.stream_plan`); a copy."""
    out = np.array(levels, np.int64)
    _coarsen(table, screen_errors(table, camera)[0], out, cap)
    return out


def _next_level(table: ChunkTable, chunk: int, level: int) -> int | None:
    later = np.flatnonzero(table.counts[chunk, level + 1:] > 0)
    return None if not later.size else level + 1 + int(later[0])


def _coarsen(table: ChunkTable, px: np.ndarray, out: np.ndarray, budget: int) -> None:
    """Coarsen ``out`` in place, smallest next screen error first, until ``budget`` splats."""
    total = table.splats(out)
    heap = []
    for c in np.flatnonzero(out >= 0).tolist():
        nxt = _next_level(table, c, int(out[c]))
        if nxt is not None:
            heap.append((float(px[c, nxt]), c, nxt))
    heapq.heapify(heap)
    while total > budget and heap:
        _, c, nxt = heapq.heappop(heap)
        total -= int(table.counts[c, out[c]] - table.counts[c, nxt])
        out[c] = nxt
        after = _next_level(table, c, nxt)
        if after is not None:
            heapq.heappush(heap, (float(px[c, after]), c, after))
