"""The per-view cut through a :class:`splatgl.lod.build.LodTree`: which nodes to draw.

A node's projected size is its bounding sphere's angular radius in pixels,
``f r / (d - r)`` (``d`` the distance from the camera centre to the sphere's centre, ``f`` the
larger focal length; infinite when the camera is inside the sphere).  A parent's sphere holds
its children's, so along any path from the root the size only falls: the cut at threshold
``T`` is every node of size <= T whose parent is larger, plus the leaves still larger than T.
It is found top-down, level by level, over index arrays (vectorised NumPy): a level's
candidates are the children of the previous level's nodes that were too large.  Nodes whose
sphere lies wholly outside the view frustum are dropped with their subtrees (nothing in them
can touch the image): the camera's own (:func:`splatgl.cameras.view.frustum_of`), which for a
lens camera is every direction (a fisheye's: its cone).

With a transition band (:func:`select_cut_weights`) nodes near the threshold are drawn as a
blend of parent and children (opacity weights), so the cut changes continuously as the camera
moves.  With a splat budget the threshold is searched for the finest cut that fits
(:mod:`splatgl.lod.cut_budget`).
"""

from __future__ import annotations

import threading
from dataclasses import dataclass

import numpy as np

from ..cameras.camera import Camera
from ..cameras.model import CullKind
from ..cameras.view import anchored_camera, frustum_of
from ..order import kernels

kernels.register(f"{__package__}._cut_numba")  # the compiled cut_level (numba, where installed)

#: Default threshold: nodes whose sphere projects to at most this many pixels (radius) stand
#: for their subtree.
DEFAULT_THRESHOLD_PX = 1.0
#: Default transition band, a ratio: nodes whose projected size is between the threshold and
#: this many times it are drawn as a blend of themselves and their children (2: about one
#: level of the tree, whose radii roughly halve per level).
DEFAULT_BAND = 2.0


#: A level is evaluated whole (contiguous, blocked) rather than gathered when its candidates
#: are at least this fraction of it: a gather costs several times a contiguous pass.
DENSE_FRACTION = 0.25


class CutTooLarge(Exception):
    """A cut abandoned before the level whose candidates would take it past ``max_nodes``:
    ``nodes``, the nodes drawn above that level plus its candidates."""

    def __init__(self, nodes: int):
        super().__init__(f"the cut would test {nodes} nodes")
        self.nodes = int(nodes)


@dataclass(frozen=True)
class CutData:
    """The view-independent arrays of the cut (from a tree): ``centres`` (3, M) float32 node
    means relative to ``anchor`` (the node scene's), ``radius`` (M,) float32, ``offsets``,
    ``branching``; ``dense``: the share of a level its candidates make for the NumPy cut to
    test it whole (above 1, never: for arrays read on demand; the same cut either way)."""

    centres: np.ndarray
    radius: np.ndarray
    offsets: np.ndarray
    branching: int
    anchor: np.ndarray
    dense: float = DENSE_FRACTION

    @classmethod
    def from_tree(cls, tree) -> "CutData":
        anchor = tree.nodes.anchor
        centres = np.ascontiguousarray((tree.nodes.means.astype(np.float64) - anchor).T, np.float32)
        return cls(centres, tree.radius, tree.offsets, tree.branching, anchor)

    def columns(self) -> tuple | None:
        """``(cx, cy, cz, radius, anchor)`` for the compiled cut: float32 columns, relative to
        :attr:`anchor` with ``anchor`` None, or as stored with ``anchor`` to take off (a lazily
        read tree's mapped spheres); None where the compiled cut cannot read them (NumPy's)."""
        columns = getattr(self.centres, "columns", None)
        if columns is not None:
            return columns()
        return self.centres[0], self.centres[1], self.centres[2], self.radius, None

    @property
    def slice_rows(self) -> int:
        """Rows of one slice of the compiled cut's candidates (0: a level at once)."""
        return int(getattr(self.centres, "slice_rows", 0))

    def release(self, lo: int, hi: int, tested: int) -> None:
        """After a slice of the compiled cut (``tested`` nodes among rows ``lo:hi``): let a
        lazily read tree's sphere pages go and count what was read (nothing otherwise)."""
        release = getattr(self.centres, "release", None)
        if release is not None:
            release(lo, hi, tested)


#: Rows per block of a dense level pass (float32 temporaries stay in cache).
BLOCK = 1 << 15
#: Per-thread scratch of the compiled cut (a level's sizes and frustum flags), reused between
#: views: fresh arrays of a few 10 MB cost their page faults on every view.
_SCRATCH = threading.local()


#: The node test of each cull kind (the compiled pass's ``kind``): the four side planes, the box
#: (only the plane behind the camera), the sphere (every direction; a fisheye's cone).
NODE_TESTS = {CullKind.FRUSTUM: 0, CullKind.BOX: 1, CullKind.SPHERE: 2}
#: Radians a node may lie beyond a fisheye's angle limit and still be kept (float32 rounding).
CONE_MARGIN = 1e-4


class _NodeTest:
    """Per-view constants of the size and frustum tests, from the camera's frustum
    (:func:`splatgl.cameras.view.frustum_of`: its cull kind and planes)."""

    def __init__(self, data: CutData, camera: Camera):
        cam = anchored_camera(camera, data.anchor)
        frustum = frustum_of(cam)
        self.r = cam.rotation.astype(np.float32)
        self.t = cam.translation.astype(np.float32)
        self.scale = np.float32(camera.scale)
        self.f = np.float32(max(camera.fx, camera.fy))
        self.kind = NODE_TESTS[frustum.kind]
        # (slope, sqrt(1 + slope^2)) of the four side planes, per axis; SPHERE: the angle limit
        self.planes = np.array([v for side in frustum.sides for v in side], np.float32)
        if self.kind == 2:
            limit = np.pi if frustum.angle_limit is None else frustum.angle_limit
            self.planes[0] = limit + CONE_MARGIN

    def test(self, c: np.ndarray, rad: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(projected radius in px, sphere touches the frustum) for centres (3, K), radii (K,)."""
        r, t = self.r, self.t
        rad = rad * self.scale
        p = [c[0] * r[i, 0] + c[1] * r[i, 1] + c[2] * r[i, 2] + t[i] for i in range(3)]
        inside = p[2] + rad > 0
        if self.kind == 1:
            return rad * self.f, inside
        d = np.sqrt(p[0] * p[0] + p[1] * p[1] + p[2] * p[2])
        gap = d - rad
        with np.errstate(divide="ignore", invalid="ignore"):
            size = np.where(gap > 0, self.f * rad / gap, np.inf)
            if self.kind == 2:   # the angle to the axis, less the sphere's angular radius
                rho = np.hypot(p[0].astype(np.float64), p[1])
                off = np.arctan2(rho, p[2]) - np.arcsin(np.minimum(rad / d, 1.0).astype(np.float64))
                return size, (gap <= 0) | (off <= self.planes[0])
        pl = self.planes
        for coord, (lo, n_lo, hi, n_hi) in zip(p[:2], (pl[0:4], pl[4:8])):
            inside &= coord - hi * p[2] <= rad * n_hi
            inside &= lo * p[2] - coord <= rad * n_lo
        return size, inside


def _dense(data: CutData, view: _NodeTest, lo: int, hi: int):
    """Sizes and frustum flags of the contiguous node rows lo:hi, block by block."""
    size = np.empty(hi - lo, np.float32)
    inside = np.empty(hi - lo, bool)
    for s in range(lo, hi, BLOCK):
        e = min(hi, s + BLOCK)
        size[s - lo:e - lo], inside[s - lo:e - lo] = view.test(data.centres[:, s:e], data.radius[s:e])
    return size, inside


def expansion(size: np.ndarray, threshold_px: float, band: float) -> np.ndarray:
    """How far each node is replaced by its children, in [0, 1], from its projected size
    (float32 px): 0 at or below ``threshold_px``, 1 from ``band * threshold_px`` up, linear in
    between (``band`` > 1: the transition band, a ratio; above the threshold, so the band costs
    only the partly drawn parents, not a finer cut); ``band`` == 1: a step at the threshold."""
    if not np.isfinite(threshold_px):  # the root level's cut
        return np.zeros(size.shape, np.float32)
    t = np.float32(threshold_px)
    if band <= 1.0:
        return (size > t).astype(np.float32)
    e = (size - t) * np.float32(1.0 / (threshold_px * (band - 1.0)))
    return np.clip(e, np.float32(0.0), np.float32(1.0), out=e)


def level_leaves(offsets: np.ndarray, branching: int, level: int, local: np.ndarray,
                 weights: np.ndarray | None) -> float:
    """Leaves that nodes ``local`` (ascending, indices within ``level``) stand for, each times
    its weight (None: 1): ``branching ** level`` each, fewer for the level's last node, which
    holds only the leaves left over."""
    if not local.size:
        return 0.0
    w = np.ones(local.size) if weights is None else weights.astype(np.float64)
    span = branching ** level
    total = float(w.sum()) * span
    n_leaves = int(offsets[1] - offsets[0])
    last = int(offsets[level + 1] - offsets[level]) - 1
    if local[-1] == last:
        total -= float(w[-1]) * (span - (n_leaves - last * span))
    return total


def select_cut_weights(data: CutData, camera: Camera, threshold_px: float = DEFAULT_THRESHOLD_PX,
                       band: float = 1.0, leaves_at: float | None = None, kern=None,
                       max_nodes: int | None = None
                       ) -> tuple[np.ndarray | None, np.ndarray | None]:
    """The cut with a transition band: ``(rows, weights)``, rows (K,) int64 ascending, weights
    (K,) float32 in (0, 1] (the factor on each node's opacity), or None when every weight is 1.

    A node's expansion ``e`` (:func:`expansion`) rises from 0 to 1 as its projected size crosses
    the band ``[T, band T]``; it is drawn with weight ``A (1 - e)``, where ``A`` is the product
    of its ancestors' ``e``, and its children are visited while ``A e > 0``.  Along every
    root-to-leaf path in view the weights sum to 1 (they telescope), and as the camera moves
    they change continuously with the sizes: a parent fades out as its children fade in, with
    no jump.  A weight scales the node's optical depth: opacity ``o`` is drawn as
    ``1 - (1 - o) ** w`` (so a parent and its children at weights ``w`` and ``1 - w`` cover what
    either covers alone where they overlap).  ``band`` == 1 is the plain cut
    (:func:`select_cut`): every weight 1.

    Level by level from the root: ``carry`` holds, over the level above's nodes, ``A e`` (0 for
    nodes not expanded).  A level whose candidates are many is evaluated whole (contiguous) and
    masked; otherwise only the candidates are gathered.

    ``leaves_at`` (nodes per leaf): before the leaf level, the largest of all, if the cut so far
    plus every candidate leaf would draw at least this many nodes per leaf they stand for,
    return ``(None, None)`` without testing the leaves: the caller draws the leaves instead
    (the candidates outside the view count as drawn here, which only errs towards the leaves,
    whose image is full detail's).

    ``max_nodes``: :class:`CutTooLarge` before a level whose candidates would take the nodes
    drawn so far past it (a cut far over a budget tests only about ``max_nodes`` nodes).

    ``kern``: :func:`splatgl.order.kernels.for_view`'s kernels, whose ``cut_level`` walks the same
    levels compiled, over the candidates only (the same rows and weights); None: NumPy.
    """
    offsets, b = data.offsets, data.branching
    view = _NodeTest(data, camera)
    if kern is not None and data.columns() is not None:
        return _compiled_cut(kern, data, view, threshold_px, band, leaves_at, max_nodes)
    top = len(offsets) - 2
    blend = band > 1.0
    # The level above's expanded nodes (local indices, ascending) and their carry A * e (float32,
    # nonzero), None above the top: kept sparse, so a level's arrays are its candidates' (a
    # whole level's only where most of it is a candidate).
    par = vals = None
    rows, weights = [], []
    drawn_all = 0
    nodes = covered = 0.0  # so far: nodes drawn, and leaves they stand for (leaves_at only)
    for level in range(top, -1, -1):
        lo, hi = int(offsets[level]), int(offsets[level + 1])
        n = hi - lo
        n_cand = n if par is None else (
            par.size * b - (max(0, int(par[-1]) * b + b - n) if par.size else 0))
        if n_cand == 0:
            break
        if max_nodes is not None and drawn_all + n_cand > max_nodes:
            raise CutTooLarge(drawn_all + n_cand)
        dense = n_cand >= data.dense * n
        if par is None:   # the top level: every node a candidate, of weight 1
            local, a_cand = np.arange(n), np.ones(n, np.float32)
        else:   # the candidates (ascending) and their weights
            local = (par[:, None] * b + np.arange(b)).ravel()
            a_cand = np.repeat(vals, b)
            fits = local < n
            local, a_cand = local[fits], a_cand[fits]
        if dense:   # a level's worth of candidate weights
            if par is None:
                above = np.ones(n, np.float32)
            else:
                above = np.zeros(n, np.float32)
                above[local] = a_cand
        if (level == 0 and leaves_at is not None
                and nodes + n_cand >= leaves_at * (covered + float(
                    (above if dense else a_cand).sum(dtype=np.float64)))):
            return None, None
        if dense:  # whole level, contiguous, masked
            size, inside = _dense(data, view, lo, hi)
            above[~inside] = 0
            e = np.zeros(n, np.float32) if level == 0 else expansion(size, threshold_px, band)
            drawn = np.flatnonzero((above > 0) & (e < 1))
            carry = above * e
            par = np.flatnonzero(carry)
            vals = carry[par]
            a, e = above[drawn], e[drawn]
        else:  # only the candidates, gathered
            size, inside = view.test(data.centres[:, local + lo], data.radius[local + lo])
            local, size = local[inside], size[inside]
            e = np.zeros(local.size, np.float32) if level == 0 else expansion(size, threshold_px, band)
            a = a_cand[inside]
            carry = a * e
            expanded = carry != 0
            par, vals = local[expanded], carry[expanded]
            keep = e < 1
            drawn, a, e = local[keep], a[keep], e[keep]
        rows.append(drawn + lo)
        drawn_all += drawn.size
        if blend:
            weights.append(a * (1 - e))
        if leaves_at is not None:
            nodes += drawn.size
            covered += level_leaves(offsets, b, level, drawn, weights[-1] if blend else None)
    if not rows:
        return np.zeros(0, np.int64), None
    # Levels occupy ascending row ranges and were visited top-down: reversed, they are sorted.
    rows_all = np.concatenate(rows[::-1])
    return rows_all, (np.concatenate(weights[::-1]) if blend else None)


def _compiled_cut(kern, data: CutData, view: _NodeTest, threshold_px: float, band: float,
                  leaves_at: float | None, max_nodes: int | None = None
                  ) -> tuple[np.ndarray | None, np.ndarray | None]:
    """:func:`select_cut_weights` through the compiled ``cut_level``, over ``data.columns()``,
    level by level from the top.  Each level's drawn rows are stacked from the outputs' end
    downwards, the top level highest: with level 0 lowest that is the rows' ascending order
    (only the tail's pages are touched); before a level, room for all its candidates is taken
    below the stack.  A level's candidates are kept as their parents (local index, carry
    ``A e``), four times fewer, and visited in slices of at most ``data.slice_rows`` rows, the
    sphere pages of each let go after it (:meth:`CutData.release`)."""
    cx, cy, cz, radius, anchor = data.columns()
    offsets, b = data.offsets, int(data.branching)
    levels = len(offsets) - 1
    n_all, n_leaves = int(offsets[-1]), int(offsets[1] - offsets[0])
    # the outputs' used part never passes max_nodes (the cut is abandoned first)
    size = n_all if max_nodes is None else min(n_all, int(max_nodes) + 1)
    out_rows, out_w = np.empty(size, np.int64), np.empty(size, np.float32)
    finite = bool(np.isfinite(threshold_px))
    mode = 0 if not finite else (1 if band <= 1.0 else 2)
    t = np.float32(threshold_px if finite else 0.0)
    ramp = np.float32(1.0 / (threshold_px * (band - 1.0)) if mode == 2 else 0.0)
    blend = band > 1.0
    test = (view.r, view.t, view.scale, view.f, view.kind, view.planes)
    scratch = _scratch(data)
    pos = size
    par, par_c = np.zeros(1, np.int64), np.ones(1, np.float32)  # one parent above the top
    n_cand = int(offsets[levels] - offsets[levels - 1])
    nodes = covered = 0.0   # so far: nodes drawn and the leaves they stand for (leaves_at)
    for level in range(levels - 1, -1, -1):
        if n_cand == 0:
            break
        lo, n = int(offsets[level]), int(offsets[level + 1] - offsets[level])
        fan = n if level == levels - 1 else b   # children per parent
        if max_nodes is not None and size - pos + n_cand > max_nodes:
            raise CutTooLarge(size - pos + n_cand)
        if (level == 0 and leaves_at is not None and nodes + n_cand >= leaves_at * (
                covered + kern.candidate_weight(par, par_c, fan, n))):
            return None, None
        below = int(offsets[level] - offsets[level - 1]) if level else 0
        nxt, nxt_c = np.empty(n_cand + 1, np.int64), np.empty(n_cand + 1, np.float32)
        dense = n_cand >= data.dense * n
        if dense:
            kern.level_test(cx, cy, cz, radius, anchor, lo, n, *test, *scratch)
        base = pos - n_cand
        counts, sums = np.zeros(3, np.int64), np.zeros(2)
        j = 0
        while j < par.size:
            j0, j = j, kern.cut_level(cx, cy, cz, radius, anchor, *test, mode, t, ramp, blend,
                                      lo, n, fan, below, level, b, par, par_c, j,
                                      data.slice_rows, dense, *scratch, out_rows, out_w, base,
                                      nxt, nxt_c, counts, sums)
            first = par[j0:j] * fan
            data.release(lo + int(first[0]), lo + min(int(first[-1]) + fan, n),
                         int((np.minimum(first + fan, n) - first).sum()))
        d, m, n_cand = (int(v) for v in counts)
        out_rows[pos - d:pos] = out_rows[base:base + d]   # down against the stack
        out_w[pos - d:pos] = out_w[base:base + d]
        pos -= d
        if leaves_at is not None and d:   # level_leaves of the drawn rows
            span = float(b) ** level
            stands_for = sums[0] * span
            if out_rows[pos + d - 1] - lo == n - 1:
                stands_for -= sums[1] * (span - (n_leaves - (n - 1) * span))
            nodes += d
            covered += stands_for
        par, par_c = nxt[:m], nxt_c[:m]
    rows, weights = out_rows[pos:], out_w[pos:]
    if pos > rows.size:   # the tail alone, so that the candidates' room below it is freed
        rows, weights = rows.copy(), weights.copy()
    return rows, (weights if blend else None)


def _scratch(data: CutData) -> tuple[np.ndarray, np.ndarray]:
    """A whole level's sizes and frustum flags (the compiled cut's dense levels), per thread
    and kept (fresh arrays of a few 10 MB cost their page faults on every view); none for a
    tree whose levels are never tested whole."""
    if data.dense > 1.0:
        return np.empty(1, np.float32), np.empty(1, bool)
    widest = int(np.diff(data.offsets).max())
    scratch = getattr(_SCRATCH, "arrays", None)
    if scratch is None or scratch[0].size < widest:
        scratch = _SCRATCH.arrays = np.empty(widest, np.float32), np.empty(widest, bool)
    return scratch


def select_cut(data: CutData, camera: Camera, threshold_px: float = DEFAULT_THRESHOLD_PX) -> np.ndarray:
    """(K,) int64 node rows of the cut at ``threshold_px`` (no band), ascending: every node in
    view of size <= threshold_px whose parent is larger, plus the leaves still larger."""
    return select_cut_weights(data, camera, threshold_px)[0]
