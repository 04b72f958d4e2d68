"""The level-of-detail cut's selection as one compiled pass (numba); imported only through
:mod:`splatgl.order.kernels` (registered by :mod:`splatgl.lod.cut`), which keeps numba optional.

:func:`cut_pass` walks the tree top-down as :func:`splatgl.lod.cut.select_cut_weights` does, but
over each level's candidates only, with no per-level NumPy calls: the same float32 operations
in the same order (``_NodeTest.test``'s size and frustum tests, :func:`~splatgl.lod.cut.expansion`,
the weights ``a (1 - e)`` and the carry ``a e``), so the same rows and the same weight bits
(tested against the NumPy path).  The one float64 decision, whether the cut would draw at
least ``leaves_at`` nodes per leaf, sums in another order than NumPy and could differ from it
only where the two sides are equal to rounding.
"""

from __future__ import annotations

import math

import numba
import numpy as np

F32 = np.float32
#: What :func:`splatgl.order.kernels.kernel` hands out from this module.
KERNELS = ("cut_pass",)


@numba.njit(inline="always", fastmath=False, error_model="numpy")
def _in_cone(p0, p1, p2, d, rad, gap, limit):
    """SPHERE: the node reaches within ``limit`` radians of the axis (float64, as NumPy's)."""
    if gap <= F32(0):
        return True
    off = (math.atan2(math.hypot(np.float64(p0), np.float64(p1)), np.float64(p2))
           - math.asin(np.float64(min(rad / d, F32(1)))))
    return off <= np.float64(limit)


@numba.njit(inline="always", fastmath=False, error_model="numpy")
def _node_test(cx, cy, cz, rad, rt, scale, f, kind, planes):
    """``(projected radius px, sphere touches the frustum)`` of one node (float32,
    ``splatgl.lod.cut._NodeTest.test``'s operations; ``kind`` 0 planes, 1 box, 2 sphere)."""
    rad = rad * scale
    p0 = cx * rt[0] + cy * rt[1] + cz * rt[2] + rt[9]
    p1 = cx * rt[3] + cy * rt[4] + cz * rt[5] + rt[10]
    p2 = cx * rt[6] + cy * rt[7] + cz * rt[8] + rt[11]
    inside = p2 + rad > F32(0)
    if kind == 1:
        return rad * f, inside
    d = np.sqrt(p0 * p0 + p1 * p1 + p2 * p2)
    gap = d - rad
    size = f * rad / gap if gap > F32(0) else F32(np.inf)
    if kind == 2:
        return size, _in_cone(p0, p1, p2, d, rad, gap, planes[0])
    inside = (inside and p0 - planes[2] * p2 <= rad * planes[3]
              and planes[0] * p2 - p0 <= rad * planes[1]
              and p1 - planes[6] * p2 <= rad * planes[7]
              and planes[4] * p2 - p1 <= rad * planes[5])
    return size, inside


@numba.njit(inline="always", fastmath=False, error_model="numpy")
def _level_test(cx, cy, cz, radius, lo, n, rt, scale, f, kind, planes, sizes, inside):
    """:func:`_node_test` of the rows ``lo:lo + n`` into ``sizes`` / ``inside``, as one loop
    without branches (for a level whose candidates are most of it: LLVM vectorises it)."""
    for q in range(n):
        size, ins = _node_test_flat(cx[lo + q], cy[lo + q], cz[lo + q], radius[lo + q], rt,
                                    scale, f, kind, planes)
        sizes[q] = size
        inside[q] = ins


@numba.njit(inline="always", fastmath=False, error_model="numpy")
def _node_test_flat(cx, cy, cz, rad, rt, scale, f, kind, planes):
    """:func:`_node_test`, every operation done and the results selected (no early exits)."""
    rad = rad * scale
    p0 = cx * rt[0] + cy * rt[1] + cz * rt[2] + rt[9]
    p1 = cx * rt[3] + cy * rt[4] + cz * rt[5] + rt[10]
    p2 = cx * rt[6] + cy * rt[7] + cz * rt[8] + rt[11]
    front = p2 + rad > F32(0)
    d = np.sqrt(p0 * p0 + p1 * p1 + p2 * p2)
    gap = d - rad
    q = f * rad / gap
    persp = q if gap > F32(0) else F32(np.inf)
    sides = ((p0 - planes[2] * p2 <= rad * planes[3]) & (planes[0] * p2 - p0 <= rad * planes[1])
             & (p1 - planes[6] * p2 <= rad * planes[7]) & (planes[4] * p2 - p1 <= rad * planes[5]))
    if kind == 1:
        return rad * f, front
    if kind == 2:
        return persp, _in_cone(p0, p1, p2, d, rad, gap, planes[0])
    return persp, front & sides


@numba.njit(inline="always", fastmath=False, error_model="numpy")
def _expansion(size, mode, t, k):
    """:func:`splatgl.lod.cut.expansion` of one size: mode 0 the root level's cut (0), 1 a step
    at ``t``, 2 the ramp ``(size - t) k`` clipped to [0, 1] (a NaN stays NaN, as np.clip)."""
    if mode == 0:
        return F32(0)
    if mode == 1:
        return F32(1) if size > t else F32(0)
    e = (size - t) * k
    if e < F32(0):
        return F32(0)
    if e > F32(1):
        return F32(1)
    return e


@numba.njit(cache=True, nogil=True, fastmath=False, boundscheck=False, error_model="numpy")
def cut_pass(cx, cy, cz, radius, offsets, branching, rot, trans, scale, f, kind, planes,
             mode, t, k, blend, leaves_at, max_nodes, dense_fraction, sizes, inside, out_rows,
             out_w):
    """The cut of :func:`splatgl.lod.cut.select_cut_weights` into the tails ``out_rows[pos:]``
    (int64, rows ascending) and ``out_w[pos:]`` (float32 weights, 1 without ``blend``), both at
    least the node count long.  ``kind``: 0 the side planes, 1 the box, 2 the sphere
    (:data:`splatgl.lod.cut.NODE_TESTS`); ``planes`` (8,) float32 per axis ``lo, n_lo, hi,
    n_hi`` (the sphere: its angle limit first);
    ``mode``, ``t``, ``k`` as :func:`_expansion` takes them; ``leaves_at`` < 0 for none.  A
    level whose candidates are at least ``dense_fraction`` of it is tested whole first
    (:func:`_level_test`, into the scratch ``sizes`` float32 / ``inside`` bool, each at least
    the largest level long).  Returns ``pos``, or -1 when the cut would draw at least
    ``leaves_at`` nodes per leaf (draw the leaves instead), or ``-2 - count`` when before a
    level the nodes drawn so far plus its candidates (``count``) exceed ``max_nodes`` (>= 0;
    -1 for no limit: :class:`splatgl.lod.cut.CutTooLarge`)."""
    rt = (rot[0, 0], rot[0, 1], rot[0, 2], rot[1, 0], rot[1, 1], rot[1, 2],
          rot[2, 0], rot[2, 1], rot[2, 2], trans[0], trans[1], trans[2])
    levels = offsets.size - 1
    n_leaves = offsets[1] - offsets[0]
    # Each level's drawn rows (ascending) are stacked from the outputs' end downwards, the top
    # level highest: with level 0 lowest that is the rows' ascending order (so no pass moves
    # them; only the pages of the tail are touched).  Before a level, room for all its
    # candidates is taken below the stack.
    pos = out_rows.size
    # A level's candidates are the children of the level above's expanded nodes, kept as those
    # parents (local index, carry A e) rather than the children, four times fewer; the top
    # level's candidates are all its nodes (a single parent of weight 1 standing above them).
    top = offsets[levels] - offsets[levels - 1]
    par = np.zeros(1, np.int64)
    par_c = np.ones(1, np.float32)
    n_cand = top
    nodes = 0.0
    covered = 0.0
    for level in range(levels - 1, -1, -1):
        if n_cand == 0:
            break
        lo = offsets[level]
        n = offsets[level + 1] - lo
        fan = n if level == levels - 1 else branching  # children per parent
        if max_nodes >= 0 and out_rows.size - pos + n_cand > max_nodes:
            return -2 - (out_rows.size - pos + n_cand)
        if level == 0 and leaves_at >= 0.0:
            s = 0.0  # the candidates' summed weight A (each parent's carry, per child)
            for j in range(par.size):
                s += np.float64(par_c[j]) * (min(par[j] * fan + fan, n) - par[j] * fan)
            if nodes + n_cand >= leaves_at * (covered + s):
                return -1
        below = offsets[level] - offsets[level - 1] if level else 0
        # this level's expanded nodes (at most all of it; one spare slot at the leaves, which
        # expand nothing but are written to unconditionally below)
        nxt = np.empty(n if level else 1, np.int64)
        nxt_c = np.empty(nxt.size, np.float32)
        m = 0
        n_next = 0
        dense = n_cand >= dense_fraction * n
        if dense:
            _level_test(cx, cy, cz, radius, lo, n, rt, scale, f, kind, planes, sizes, inside)
        base = pos - n_cand
        d = 0
        w_sum = 0.0
        last_w = 0.0
        for j in range(par.size):
            a = par_c[j]
            for local in range(par[j] * fan, min(par[j] * fan + fan, n)):
                row = lo + local
                if dense:
                    size, ins = sizes[local], inside[local]
                else:
                    size, ins = _node_test(cx[row], cy[row], cz[row], radius[row], rt, scale,
                                           f, kind, planes)
                # written unconditionally and counted by the tests (no branches to mispredict:
                # slots past the count are overwritten or never read)
                e = F32(0) if level == 0 else _expansion(size, mode, t, k)
                w = a * (F32(1) - e) if blend else F32(1)
                drawn = ins & (e < F32(1))
                out_rows[base + d] = row
                out_w[base + d] = w
                w_sum += np.float64(w) if drawn else 0.0
                last_w = np.float64(w) if drawn else last_w
                d += drawn
                c = a * e
                # expanded: nonzero carry (a NaN too, as np.count_nonzero counts it)
                expand = ins & (level > 0) & (c != F32(0))
                nxt[m] = local
                nxt_c[m] = c
                m += expand
                n_next += (min(local * branching + branching, below) - local * branching
                           if expand else 0)
        # the drawn rows down against the stack (backwards: the ranges may overlap)
        for q in range(d - 1, -1, -1):
            out_rows[pos - d + q] = out_rows[base + q]
            out_w[pos - d + q] = out_w[base + q]
        pos -= d
        if leaves_at >= 0.0 and d:  # splatgl.lod.cut.level_leaves of the drawn rows
            span = np.float64(branching) ** level
            stands_for = w_sum * span
            last = n - 1
            if out_rows[pos + d - 1] - lo == last:
                stands_for -= last_w * (span - (n_leaves - last * span))
            nodes += d
            covered += stands_for
        par = nxt[:m]
        par_c = nxt_c[:m]
        n_cand = n_next
    return pos


def warm_up() -> None:
    """Compile (or load from numba's cache) for the argument types the cut uses."""
    f4 = np.zeros(3, np.float32)
    cut_pass(f4, f4, f4, f4, np.array([0, 2, 3], np.int64), 2, np.eye(3, dtype=np.float32),
             np.zeros(3, np.float32), F32(1), F32(1), 0, np.zeros(8, np.float32), 2, F32(1),
             F32(1), True, -1.0, -1, 0.25, np.zeros(3, np.float32), np.zeros(3, np.bool_),
             np.zeros(3, np.int64), np.zeros(3, np.float32))
