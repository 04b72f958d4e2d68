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


def _sizes_and_inside(data: CutData, ids: np.ndarray, camera: Camera):
    """(projected radius in px, sphere touches the frustum) for the nodes ``ids``."""
    cam = anchored_camera(camera, data.anchor)
    r = cam.rotation.astype(np.float32)
    t = cam.translation.astype(np.float32)
    c = data.centres[:, ids]
    rad = data.radius[ids] * np.float32(camera.scale)
    p = [c[0] * r[i, 0] + c[1] * r[i, 1] + c[2] * r[i, 2] + t[i] for i in range(3)]
    d = np.sqrt(p[0] * p[0] + p[1] * p[1] + p[2] * p[2])
    f = np.float32(max(camera.fx, camera.fy))
    gap = d - rad
    with np.errstate(divide="ignore"):
        size = np.where(gap > 0, f * rad / np.maximum(gap, 1e-30), np.inf)
    inside = p[2] + rad > 0
    if not camera.is_orthographic:
        for coord, fl, cc, extent in ((p[0], camera.fx, camera.cx, camera.width),
                                      (p[1], camera.fy, camera.cy, camera.height)):
            lo, hi = -cc / fl, (extent - cc) / fl
            inside &= (coord - np.float32(hi) * p[2]) <= rad * np.float32(np.sqrt(1 + hi * hi))
            inside &= (np.float32(lo) * p[2] - coord) <= rad * np.float32(np.sqrt(1 + lo * lo))
    else:
        size = rad * f  # orthographic: the sphere's radius in pixels
    return size, inside


def select_cut(data: CutData, camera: Camera, threshold_px: float = DEFAULT_THRESHOLD_PX) -> np.ndarray:
    """(K,) int64 node rows of the cut at ``threshold_px``, ascending."""
    offsets, b = data.offsets, data.branching
    top = len(offsets) - 2
    cand = np.arange(offsets[top], offsets[top + 1])
    chosen = []
    for level in range(top, -1, -1):
        if not cand.size:
            break
        size, inside = _sizes_and_inside(data, cand, camera)
        cand, size = cand[inside], size[inside]
        if level == 0:
            chosen.append(cand)
            break
        fine = size <= threshold_px
        chosen.append(cand[fine])
        coarse = cand[~fine] - offsets[level]
        kids = (coarse[:, None] * b + np.arange(b)).ravel()
        cand = kids[kids < offsets[level] - offsets[level - 1]] + offsets[level - 1]
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
