"""The per-view cut through a :class:`splatgl.lod.build.LodTree`: which nodes to draw.

A node's projected size is its bounding sphere's angular radius in pixels,
``f r / (d - r)`` (``d`` the distance from the camera centre to the sphere's centre, ``f`` the
larger focal length; infinite when the camera is inside the sphere).  A parent's sphere holds
its children's, so along any path from the root the size only falls: the cut at threshold
``T`` is every node of size <= T whose parent is larger, plus the leaves still larger than T.
It is found top-down, level by level, over index arrays (vectorised NumPy): a level's
candidates are the children of the previous level's nodes that were too large.  Nodes whose
sphere lies wholly outside the view frustum are dropped with their subtrees (nothing in them
can touch the image).

With a splat budget the threshold is searched (on a log scale) for the finest cut that fits.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..camera import Camera
from ..project import anchored_camera

#: Default threshold: nodes whose sphere projects to at most this many pixels (radius) stand
#: for their subtree.
DEFAULT_THRESHOLD_PX = 1.0
#: Budget search: at most this many cuts per view, stopping within this fraction of the budget.
BUDGET_STEPS = 8
BUDGET_TOLERANCE = 0.1


@dataclass(frozen=True)
class CutData:
    """The view-independent arrays of the cut (from a tree): ``centres`` (3, M) float32 node
    means relative to ``anchor`` (the node scene's), ``radius`` (M,) float32, ``offsets``,
    ``branching``."""

    centres: np.ndarray
    radius: np.ndarray
    offsets: np.ndarray
    branching: int
    anchor: np.ndarray

    @classmethod
    def from_tree(cls, tree) -> "CutData":
        anchor = tree.nodes.anchor
        centres = np.ascontiguousarray((tree.nodes.means.astype(np.float64) - anchor).T, np.float32)
        return cls(centres, tree.radius, tree.offsets, tree.branching, anchor)


#: A level is evaluated whole (contiguous, blocked) rather than gathered when its candidates
#: are at least this fraction of it: a gather costs several times a contiguous pass.
DENSE_FRACTION = 0.25
#: Rows per block of a dense level pass (float32 temporaries stay in cache).
BLOCK = 1 << 15


class _View:
    """Per-view constants of the size and frustum tests."""

    def __init__(self, data: CutData, camera: Camera):
        cam = anchored_camera(camera, data.anchor)
        self.r = cam.rotation.astype(np.float32)
        self.t = cam.translation.astype(np.float32)
        self.scale = np.float32(camera.scale)
        self.f = np.float32(max(camera.fx, camera.fy))
        self.ortho = camera.is_orthographic
        self.planes = []  # (slope, sqrt(1 + slope^2)) of the four side planes, per axis
        for fl, cc, extent in ((camera.fx, camera.cx, camera.width), (camera.fy, camera.cy, camera.height)):
            lo, hi = -cc / fl, (extent - cc) / fl
            self.planes.append((np.float32(lo), np.float32(np.sqrt(1 + lo * lo)),
                                np.float32(hi), np.float32(np.sqrt(1 + hi * hi))))

    def test(self, c: np.ndarray, rad: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(projected radius in px, sphere touches the frustum) for centres (3, K), radii (K,)."""
        r, t = self.r, self.t
        rad = rad * self.scale
        p = [c[0] * r[i, 0] + c[1] * r[i, 1] + c[2] * r[i, 2] + t[i] for i in range(3)]
        inside = p[2] + rad > 0
        if self.ortho:
            return rad * self.f, inside
        d = np.sqrt(p[0] * p[0] + p[1] * p[1] + p[2] * p[2])
        gap = d - rad
        with np.errstate(divide="ignore", invalid="ignore"):
            size = np.where(gap > 0, self.f * rad / gap, np.inf)
        for coord, (lo, n_lo, hi, n_hi) in zip(p[:2], self.planes):
            inside &= coord - hi * p[2] <= rad * n_hi
            inside &= lo * p[2] - coord <= rad * n_lo
        return size, inside


def _dense(data: CutData, view: _View, lo: int, hi: int):
    """Sizes and frustum flags of the contiguous node rows lo:hi, block by block."""
    size = np.empty(hi - lo, np.float32)
    inside = np.empty(hi - lo, bool)
    for s in range(lo, hi, BLOCK):
        e = min(hi, s + BLOCK)
        size[s - lo:e - lo], inside[s - lo:e - lo] = view.test(data.centres[:, s:e], data.radius[s:e])
    return size, inside


def select_cut(data: CutData, camera: Camera, threshold_px: float = DEFAULT_THRESHOLD_PX) -> np.ndarray:
    """(K,) int64 node rows of the cut at ``threshold_px``, ascending.

    Level by level from the root: ``expanded`` marks the level's nodes that are in view and
    larger than the threshold (their children are the next level's candidates).  A level whose
    candidates are many is evaluated whole (contiguous) and masked; otherwise only the
    candidates are gathered.
    """
    offsets, b = data.offsets, data.branching
    view = _View(data, camera)
    top = len(offsets) - 2
    expanded = None  # bool mask over the level above's nodes
    chosen = []
    for level in range(top, -1, -1):
        lo, hi = int(offsets[level]), int(offsets[level + 1])
        n = hi - lo
        if expanded is None:
            cand_mask = np.ones(n, bool)
        else:
            cand_mask = np.repeat(expanded, b)[:n]
        n_cand = int(np.count_nonzero(cand_mask))
        if n_cand == 0:
            break
        if n_cand >= DENSE_FRACTION * n:
            size, inside = _dense(data, view, lo, hi)
            keep = cand_mask & inside
            if level == 0:
                chosen.append(np.flatnonzero(keep) + lo)
                break
            fine = size <= np.float32(threshold_px)
            chosen.append(np.flatnonzero(keep & fine) + lo)
            expanded = keep & ~fine
        else:
            local = np.flatnonzero(cand_mask)
            size, inside = view.test(data.centres[:, local + lo], data.radius[local + lo])
            local, size = local[inside], size[inside]
            if level == 0:
                chosen.append(local + lo)
                break
            fine = size <= np.float32(threshold_px)
            chosen.append(local[fine] + lo)
            expanded = np.zeros(n, bool)
            expanded[local[~fine]] = True
    return np.sort(np.concatenate(chosen)) if chosen else np.zeros(0, np.int64)


def select_cut_budget(data: CutData, camera: Camera, budget: int,
                      threshold_px: float = DEFAULT_THRESHOLD_PX) -> tuple[np.ndarray, float]:
    """The finest cut of at most ``budget`` nodes, not finer than ``threshold_px``:
    ``(node rows, threshold used)``.  The threshold is searched on a log scale (a cut's count
    falls roughly as the threshold squared), BUDGET_STEPS cuts at most."""
    t_ok, cut_ok = None, None
    lo, hi = threshold_px, None  # lo: known too many nodes (or the floor), hi: known to fit
    t = threshold_px
    for _ in range(BUDGET_STEPS):
        cut = select_cut(data, camera, t)
        if cut.size <= budget:
            t_ok, cut_ok, hi = t, cut, t
            if t <= threshold_px or cut.size >= (1.0 - BUDGET_TOLERANCE) * budget:
                break
        else:
            lo = t
        if hi is None:
            t = t * max(1.25, float(np.sqrt(cut.size / budget)))
        else:
            t = float(np.sqrt(lo * hi))
    if cut_ok is None:  # even the last threshold was too fine: take the root level's cut
        t_ok = float("inf")
        cut_ok = select_cut(data, camera, t_ok)
    return cut_ok, t_ok
