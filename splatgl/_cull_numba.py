"""The chunked cull's per-row work as one compiled pass (numba); imported only through
:mod:`splatgl.cull_kernel`, which keeps numba optional.

Every float32 operation is the NumPy path's own, in the same order (:func:`splatgl.cull.view_axis`
for the depths and camera-space coordinates, :func:`splatgl.cull.plane_constants`' tests), with
no fast-math, so the kept rows and the depth bits are the same (tested against the NumPy path).
"""

from __future__ import annotations

import numba
import numpy as np


@numba.njit(inline="always", fastmath=False)
def _axis(xi, yi, zi, a, b, c, t):
    """One camera axis ``((x a + y b) + z c) + t`` in float32, :func:`splatgl.cull.view_axis`'s order."""
    d = xi * a
    d = d + yi * b
    d = d + zi * c
    return d + t


@numba.njit(inline="always", fastmath=False)
def _between_planes(u, d, rad, a_hi, b_hi, a_lo, b_lo):
    """The side-plane test of one image axis (:func:`splatgl.cull.plane_constants`)."""
    return u <= rad * b_hi + d * a_hi and u >= rad * b_lo + d * a_lo


@numba.njit(cache=True, nogil=True, fastmath=False, boundscheck=False)
def chunk_pass(x, y, z, radius, faint, index, starts, flags, rot, trans, planes, near32,
               keys_u32, keys_f32, check_rows, check_p):
    """Per chunk ``k`` by ``flags[k]``: 0 skip, 1 keep every row (depth only), 2 the per-row
    near and side-plane tests.  Kept rows' keys go to ``keys_u32[2 n] = index`` and
    ``keys_f32[2 n + 1] = z`` (two views of the uint64 key buffer), except tested rows whose
    centre projects outside the image or that are faint: those go to ``check_rows`` /
    ``check_p`` (camera-space x, y, z) for the peak alpha bound.  Returns (keys, checks)."""
    r00, r01, r02 = rot[0, 0], rot[0, 1], rot[0, 2]
    r10, r11, r12 = rot[1, 0], rot[1, 1], rot[1, 2]
    r20, r21, r22 = rot[2, 0], rot[2, 1], rot[2, 2]
    t0, t1, t2 = trans[0], trans[1], trans[2]
    ax_hi, bx_hi, ax_lo, bx_lo, x_lo, x_hi = (planes[0, 0], planes[0, 1], planes[0, 2],
                                              planes[0, 3], planes[0, 4], planes[0, 5])
    ay_hi, by_hi, ay_lo, by_lo, y_lo, y_hi = (planes[1, 0], planes[1, 1], planes[1, 2],
                                              planes[1, 3], planes[1, 4], planes[1, 5])
    n = 0
    c = 0
    for k in range(flags.size):
        f = flags[k]
        if f == 0:
            continue
        a, b = starts[k], starts[k + 1]
        if f == 1:
            for i in range(a, b):
                d = _axis(x[i], y[i], z[i], r20, r21, r22, t2)
                keys_u32[2 * n] = index[i]
                keys_f32[2 * n + 1] = d
                n += 1
            continue
        for i in range(a, b):
            d = _axis(x[i], y[i], z[i], r20, r21, r22, t2)
            if not d > near32:
                continue
            rad = radius[i]
            u = _axis(x[i], y[i], z[i], r00, r01, r02, t0)
            if not _between_planes(u, d, rad, ax_hi, bx_hi, ax_lo, bx_lo):
                continue
            v = _axis(x[i], y[i], z[i], r10, r11, r12, t1)
            if not _between_planes(v, d, rad, ay_hi, by_hi, ay_lo, by_lo):
                continue
            inside = u <= d * x_hi and u >= d * x_lo and v <= d * y_hi and v >= d * y_lo
            if inside and not faint[i]:
                keys_u32[2 * n] = index[i]
                keys_f32[2 * n + 1] = d
                n += 1
            else:
                check_rows[c] = i
                check_p[c, 0] = u
                check_p[c, 1] = v
                check_p[c, 2] = d
                c += 1
    return n, c


def warm_up() -> None:
    """Compile (or load from numba's cache) the kernel for the argument types the cull uses."""
    f4, u4 = np.zeros(2, np.float32), np.zeros(2, np.uint32)
    chunk_pass(f4, f4, f4, f4, np.zeros(2, np.bool_), u4, np.array([0, 2], np.int64),
               np.array([2], np.int8), np.eye(3, dtype=np.float32), np.zeros(3, np.float32),
               np.zeros((2, 6), np.float32), np.float32(0.0), np.zeros(4, np.uint32),
               np.zeros(4, np.float32), np.zeros(2, np.int64), np.zeros((2, 3), np.float32))
