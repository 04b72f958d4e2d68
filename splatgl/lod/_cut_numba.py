"""The level-of-detail cut's selection compiled (numba); imported only through
:mod:`splatgl.order.kernels` (registered by :mod:`splatgl.lod.cut`), which keeps numba optional.

:func:`cut_level` tests one level of the tree as :func:`splatgl.lod.cut.select_cut_weights`
does, but over the level's candidates only, in one loop (:func:`splatgl.lod.cut._compiled_cut`
walks the levels top-down and slices a level's candidates by rows, so that a file's mapped
spheres can be let go slice by slice): the same float32 operations in the same order
(``_NodeTest.test``'s size and frustum tests, :func:`~splatgl.lod.cut.expansion`, the weights
``a (1 - e)`` and the carry ``a e``), so the same rows and the same weight bits (tested against
the NumPy path).  The one float64 decision, whether the cut would draw at least ``leaves_at``
nodes per leaf (:func:`candidate_weight`), sums in another order than NumPy and could differ
from it only where the two sides are equal to rounding.
"""

from __future__ import annotations

import math

import numba
import numpy as np

F32 = np.float32
#: What :func:`splatgl.order.kernels.kernel` hands out from this module.
KERNELS = ("cut_level", "level_test", "candidate_weight")


@numba.njit(inline="always", fastmath=False, error_model="numpy")
def _in_cone(p0, p1, p2, d, rad, gap, limit):
    """SPHERE: the node reaches within ``limit`` radians of the axis (float64, as NumPy's)."""
    if gap <= F32(0):
        return True
    off = (math.atan2(math.hypot(np.float64(p0), np.float64(p1)), np.float64(p2))
           - math.asin(np.float64(min(rad / d, F32(1)))))
    return off <= np.float64(limit)


@numba.njit(inline="always", fastmath=False, error_model="numpy")
def _centre(c, row, anchor, axis):
    """Coordinate ``axis`` of node ``row`` relative to the tree's anchor: ``c[row]`` itself
    where the columns are relative already (``anchor`` None, decided when compiled), else
    ``float32(float64(c[row]) - anchor[axis])``, :meth:`splatgl.lod.lazy.LazyLod.spheres`'s
    operation on a file's stored positions."""
    if anchor is None:
        return c[row]
    return F32(np.float64(c[row]) - anchor[axis])


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
def _level_test(cx, cy, cz, radius, anchor, lo, n, rt, scale, f, kind, planes, sizes, inside):
    """:func:`_node_test` of the rows ``lo:lo + n`` into ``sizes`` / ``inside``, as one loop
    without branches (for a level whose candidates are most of it: LLVM vectorises it)."""
    for q in range(n):
        row = lo + q
        size, ins = _node_test_flat(_centre(cx, row, anchor, 0), _centre(cy, row, anchor, 1),
                                    _centre(cz, row, anchor, 2), radius[row], rt, scale, f,
                                    kind, planes)
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
def level_test(cx, cy, cz, radius, anchor, lo, n, rot, trans, scale, f, kind, planes, sizes,
               inside):
    """Every node of the rows ``lo:lo + n`` tested (:func:`_level_test`) into ``sizes`` /
    ``inside``: a level whose candidates are most of it (contiguous, vectorised)."""
    rt = (rot[0, 0], rot[0, 1], rot[0, 2], rot[1, 0], rot[1, 1], rot[1, 2],
          rot[2, 0], rot[2, 1], rot[2, 2], trans[0], trans[1], trans[2])
    _level_test(cx, cy, cz, radius, anchor, lo, n, rt, scale, f, kind, planes, sizes, inside)


@numba.njit(cache=True, nogil=True, fastmath=False, boundscheck=False, error_model="numpy")
def cut_level(cx, cy, cz, radius, anchor, rot, trans, scale, f, kind, planes, mode, t, k, blend,
              lo, n, fan, below, level, branching, par, par_c, j0, row_limit, dense, sizes,
              inside, out_rows, out_w, base, nxt, nxt_c, counts, sums):
    """One level of :func:`splatgl.lod.cut.select_cut_weights`'s cut (driven level by level by
    :func:`splatgl.lod.cut._compiled_cut`), over the candidates only: the children (``fan``
    each, of the level's ``n`` nodes from row ``lo``) of the level above's expanded nodes
    ``par`` (local indices, ascending) with their carries ``par_c``, from parent ``j0`` on,
    until the candidates span more than ``row_limit`` rows (then it returns, so the caller can
    let a mapped file's pages go before the next slice; 0 for no limit).  Node centres
    ``cx, cy, cz`` (float32 columns, relative to the tree's anchor where ``anchor`` is None,
    else as stored with ``anchor`` (3,) float64 taken off: :func:`_centre`) and ``radius``;
    ``dense``: the level was tested whole into ``sizes`` / ``inside`` (:func:`level_test`).
    ``kind``: 0 the side planes, 1 the box, 2 the sphere (:data:`splatgl.lod.cut.NODE_TESTS`);
    ``planes`` (8,) float32 per axis ``lo, n_lo, hi, n_hi`` (the sphere: its angle limit
    first); ``mode``, ``t``, ``k`` as :func:`_expansion` takes them.

    The drawn rows and their weights (1 without ``blend``) go to ``out_rows`` / ``out_w`` from
    ``base`` on, the expanded nodes and their carries to ``nxt`` / ``nxt_c``; ``counts`` (int64:
    drawn, expanded, the next level's candidates) and ``sums`` (float64: the drawn weights'
    sum, the last drawn weight) carry on from slice to slice.  The same float32 operations in
    the same order as the NumPy cut (``_NodeTest.test``, ``expansion``, the weights
    ``a (1 - e)`` and carries ``a e``): the same rows and weight bits.  Returns the next
    parent to visit."""
    rt = (rot[0, 0], rot[0, 1], rot[0, 2], rot[1, 0], rot[1, 1], rot[1, 2],
          rot[2, 0], rot[2, 1], rot[2, 2], trans[0], trans[1], trans[2])
    d, m, n_next = counts[0], counts[1], counts[2]
    w_sum, last_w = sums[0], sums[1]
    first = par[j0] * fan
    j = j0
    while j < par.size:
        start = par[j] * fan
        if row_limit > 0 and j > j0 and start + fan - first > row_limit:
            break
        a = par_c[j]
        for local in range(start, min(start + fan, n)):
            row = lo + local
            if dense:
                size, ins = sizes[local], inside[local]
            else:
                size, ins = _node_test(_centre(cx, row, anchor, 0), _centre(cy, row, anchor, 1),
                                       _centre(cz, row, anchor, 2), radius[row], rt, scale, f,
                                       kind, planes)
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
        j += 1
    counts[0], counts[1], counts[2] = d, m, n_next
    sums[0], sums[1] = w_sum, last_w
    return j


@numba.njit(cache=True, nogil=True, fastmath=False, boundscheck=False, error_model="numpy")
def candidate_weight(par, par_c, fan, n):
    """The summed weight ``A`` of a level's candidates: each parent's carry ``par_c`` times its
    children (``fan`` each, the level's ``n`` nodes), summed in float64 in the parents' order."""
    s = 0.0
    for j in range(par.size):
        s += np.float64(par_c[j]) * (min(par[j] * fan + fan, n) - par[j] * fan)
    return s


def warm_up() -> None:
    """Compile (or load from numba's cache) for the argument types the cut uses: an in-memory
    tree's columns (writable, contiguous, relative to the anchor) and a lazily read tree's
    (read-only strided views of its mapped spheres, the anchor taken off here)."""
    own = np.zeros(3, np.float32)
    mapped = np.frombuffer(bytes(48), np.float32).reshape(3, 4)[:, 0]
    rot, trans = np.eye(3, dtype=np.float32), np.zeros(3, np.float32)
    planes = np.zeros(8, np.float32)
    for col, anchor in ((own, None), (mapped, np.zeros(3))):
        sizes, inside = np.zeros(3, np.float32), np.zeros(3, np.bool_)
        level_test(col, col, col, col, anchor, 0, 3, rot, trans, F32(1), F32(1), 0, planes,
                   sizes, inside)
        par, par_c = np.zeros(1, np.int64), np.ones(1, np.float32)
        cut_level(col, col, col, col, anchor, rot, trans, F32(1), F32(1), 0, planes, 2, F32(1),
                  F32(1), True, 0, 3, 3, 0, 0, 2, par, par_c, 0, 0, False, sizes, inside,
                  np.zeros(3, np.int64), np.zeros(3, np.float32), 0, np.zeros(4, np.int64),
                  np.zeros(4, np.float32), np.zeros(3, np.int64), np.zeros(2))
    candidate_weight(np.zeros(1, np.int64), np.ones(1, np.float32), 3, 3)
