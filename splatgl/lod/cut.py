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
moves.  With a splat budget the threshold is searched (on a log scale) for the finest cut that
fits.
"""

from __future__ import annotations

import threading
from dataclasses import dataclass

import numpy as np

from ..cameras.camera import Camera
from ..cameras.model import CullKind
from ..cameras.view import anchored_camera, frustum_of
from ..order import kernels

kernels.register(f"{__package__}._cut_numba")  # the compiled cut_pass (numba, where installed)

#: Default threshold: nodes whose sphere projects to at most this many pixels (radius) stand
#: for their subtree.
DEFAULT_THRESHOLD_PX = 1.0
#: Default transition band, a ratio: nodes whose projected size is between the threshold and
#: this many times it are drawn as a blend of themselves and their children (2: about one
#: level of the tree, whose radii roughly halve per level).
DEFAULT_BAND = 2.0
#: Budget search: at most this many cuts per view, stopping within this fraction of the budget.
BUDGET_STEPS = 8
BUDGET_TOLERANCE = 0.1
#: Where no cut fitted within BUDGET_STEPS: at most this many more (doubling the threshold),
#: then this many narrowing steps between the last cut too large and the first that fits.
MAX_LATE_STEPS = 40
LATE_BISECTIONS = 3
#: A budget's search abandons a trial cut past this many times the budget (CutTooLarge), so
#: its memory stays a few budgets' at any size, and steps as if the cut held that many.
ABORT_FACTOR = 3
#: The search from a nearby view's threshold (:func:`select_cut_budget_near`): at most this many
#: cuts, stepping the threshold by at least this factor until the budget is bracketed.
NEAR_STEPS = 6
NEAR_FACTOR = 1.15


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
    dense: float = 0.25

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

    ``kern``: :func:`splatgl.order.kernels.for_view`'s kernels, whose ``cut_pass`` walks the same
    levels compiled, over the candidates only (the same rows and weights); None: NumPy.
    """
    offsets, b = data.offsets, data.branching
    view = _NodeTest(data, camera)
    if kern is not None:
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
    """:func:`select_cut_weights` through the compiled ``cut_pass``."""
    n = int(data.offsets[-1])
    rows, weights = np.empty(n, np.int64), np.empty(n, np.float32)
    widest = int(np.diff(data.offsets).max())
    scratch = getattr(_SCRATCH, "arrays", None)
    if scratch is None or scratch[0].size < widest:
        scratch = _SCRATCH.arrays = np.empty(widest, np.float32), np.empty(widest, bool)
    finite = bool(np.isfinite(threshold_px))
    mode = 0 if not finite else (1 if band <= 1.0 else 2)
    ramp = 1.0 / (threshold_px * (band - 1.0)) if mode == 2 else 0.0
    pos = kern.cut_pass(data.centres[0], data.centres[1], data.centres[2], data.radius,
                          np.asarray(data.offsets, np.int64), int(data.branching), view.r, view.t,
                          view.scale, view.f, view.kind, view.planes, mode,
                          np.float32(threshold_px if finite else 0.0), np.float32(ramp),
                          band > 1.0, -1.0 if leaves_at is None else float(leaves_at),
                          -1 if max_nodes is None else int(max_nodes),
                          DENSE_FRACTION, *scratch, rows, weights)
    if pos <= -2:   # -2 - pos: the nodes drawn above the level abandoned, plus its candidates
        raise CutTooLarge(-2 - pos)
    if pos < 0:
        return None, None
    return rows[pos:], (weights[pos:] if band > 1.0 else None)


def select_cut(data: CutData, camera: Camera, threshold_px: float = DEFAULT_THRESHOLD_PX) -> np.ndarray:
    """(K,) int64 node rows of the cut at ``threshold_px`` (no band), ascending: every node in
    view of size <= threshold_px whose parent is larger, plus the leaves still larger."""
    return select_cut_weights(data, camera, threshold_px)[0]


def select_cut_budget(data: CutData, camera: Camera, budget: int,
                      threshold_px: float = DEFAULT_THRESHOLD_PX, band: float = 1.0, kern=None
                      ) -> tuple[np.ndarray, np.ndarray | None, float]:
    """The finest cut of at most ``budget`` drawn nodes, not finer than ``threshold_px``:
    ``(node rows, weights, threshold used)`` (rows and weights as :func:`select_cut_weights`
    gives them for that threshold and ``band``).  The threshold is searched on a log scale (a
    cut's count falls roughly as the threshold squared), BUDGET_STEPS cuts at most; it changes
    from view to view, so a budget's cut is not continuous along a path, band or not.
    ``kern`` as :func:`select_cut_weights` takes it.  A trial cut past ABORT_FACTOR times the
    budget is abandoned (:class:`CutTooLarge`) and counts as that many nodes."""
    ok = None
    lo, hi = threshold_px, None  # lo: known too many nodes (or the floor), hi: known to fit
    t = threshold_px
    first_fit = None  # the step of the first cut that fitted
    for step in range(BUDGET_STEPS + MAX_LATE_STEPS):
        cut, w, size = _trial_cut(data, camera, t, band, kern, budget)
        if size <= budget:
            ok, hi = (cut, w, t), t
            first_fit = step if first_fit is None else first_fit
            if t <= threshold_px or size >= (1.0 - BUDGET_TOLERANCE) * budget:
                break
        else:
            lo = t
        # Out of steps: stop.  Where no cut fitted yet (leaves larger than the threshold keep
        # the count high, so it falls far slower than the threshold squared), keep doubling the
        # threshold until one does, then narrow that last bracket LATE_BISECTIONS times.
        if first_fit is not None and step >= max(BUDGET_STEPS, first_fit + LATE_BISECTIONS + 1) - 1:
            break
        if hi is None:
            t = t * (2.0 if step + 1 >= BUDGET_STEPS else max(1.25, float(np.sqrt(size / budget))))
        else:
            t = float(np.sqrt(lo * hi))
    if ok is None:  # even the coarsest threshold tried was too fine: the root level's cut
        ok = (*select_cut_weights(data, camera, float("inf"), band, kern=kern), float("inf"))
    return ok


def _trial_cut(data: CutData, camera: Camera, t: float, band: float, kern, budget: int):
    """``(rows, weights, nodes)`` of a budget search's trial at ``t`` (rows None: abandoned)."""
    try:
        cut, w = select_cut_weights(data, camera, t, band, kern=kern,
                                    max_nodes=ABORT_FACTOR * int(budget))
    except CutTooLarge:
        return None, None, ABORT_FACTOR * int(budget) + 1
    return cut, w, int(cut.size)


def select_cut_budget_near(data: CutData, camera: Camera, budget: int, start: float,
                           threshold_px: float = DEFAULT_THRESHOLD_PX, band: float = 1.0, kern=None,
                           steps: int = NEAR_STEPS) -> tuple[np.ndarray, np.ndarray | None, float]:
    """:func:`select_cut_budget` searched from ``start``, the threshold of a view nearby (the
    last frame's): consecutive frames need about the same threshold, so two or three cuts
    usually settle it where the search from the floor takes a dozen.  Steps by the ratio of the
    count to the budget (at least NEAR_FACTOR) until bracketed, then halves the bracket on a log
    scale; where ``steps`` cuts find none that fits, the search from the floor decides."""
    ok = None
    lo = hi = None
    t = max(float(start), threshold_px) if np.isfinite(start) else threshold_px
    for _ in range(steps):
        cut, w, size = _trial_cut(data, camera, t, band, kern, budget)
        if size <= budget:
            ok, hi = (cut, w, t), t
            if t <= threshold_px or size >= (1.0 - BUDGET_TOLERANCE) * budget:
                break
        else:
            lo = t
        if hi is None:
            t *= max(NEAR_FACTOR, size / budget)
        elif lo is None:
            t = max(threshold_px, t / max(NEAR_FACTOR, float(np.sqrt(budget / max(size, 1)))))
        else:
            t = float(np.sqrt(lo * hi))
    if ok is None:
        return select_cut_budget(data, camera, budget, threshold_px, band, kern)
    return ok

