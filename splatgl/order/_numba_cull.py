"""The chunked cull's per-view work as one compiled pass (numba); imported only through
:mod:`splatgl.order.kernels` (registered by :mod:`splatgl.order.chunks`), which keeps numba
optional.

Every float32 operation is the NumPy path's own, in the same order (:func:`splatgl.order.cull.view_axis`
for the depths and camera-space coordinates, :func:`splatgl.order.cull.plane_constants`' tests), with
no fast-math, so the kept rows and the depth bits are the same (tested against the NumPy path).
The chunk classification only skips work (conservative either way), and the float64 peak bound
hands the rows it cannot call for certain back to NumPy, so those stay the same too.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from ..constants import ALPHA_MIN, LOW_PASS

#: A compiled (float64) peak-alpha bound this close to 1/255 (relative) is not trusted to fall
#: on the side of :func:`splatgl.order.cull.peak_keeps`' float32 decision, which such rows go
#: back to: float32 rounding moves that decision's exponent ``d^2 / (2 lambda)`` by less than
#: 6 ulp(u) (u the pixel coordinate: ulp 1e-3 up to 8192 px), well inside this band.
PEAK_UNSURE = 1e-2
#: What :func:`splatgl.order.kernels.kernel` hands out from this module.
KERNELS = ("view_pass", "rows_pass", "lens_pass")


@numba.njit(inline="always", fastmath=False)
def _axis(xi, yi, zi, a, b, c, t):
    """One camera axis ``((x a + y b) + z c) + t`` in float32, :func:`splatgl.order.cull.view_axis`'s order."""
    d = xi * a
    d = d + yi * b
    d = d + zi * c
    return d + t


@numba.njit(inline="always", fastmath=False)
def _between_planes(u, d, rad, a_hi, b_hi, a_lo, b_lo):
    """The side-plane test of one image axis (:func:`splatgl.order.cull.plane_constants`)."""
    return u <= rad * b_hi + d * a_hi and u >= rad * b_lo + d * a_lo


@numba.njit(inline="always", fastmath=False)
def _sphere_class(sph, k, rot, t, view, sides):
    """:meth:`splatgl.order.chunks.Spheres.classify` of sphere ``k`` (a row of ``Spheres.packed``)
    in float64: 1 accept, 0 reject, 2 test its splats."""
    cx, cy, cz = sph[k, 0], sph[k, 1], sph[k, 2]
    x = rot[0, 0] * cx + rot[0, 1] * cy + rot[0, 2] * cz + t[0]
    y = rot[1, 0] * cx + rot[1, 1] * cy + rot[1, 2] * cz + t[1]
    z = rot[2, 0] * cx + rot[2, 1] * cy + rot[2, 2] * cz + t[2]
    s, near, t_norm, scale, rounding = view[0], view[1], view[2], view[3], view[4]
    rc = sph[k, 3] * s
    reach = sph[k, 4] * scale
    slack = rounding * (math.sqrt(x * x + y * y + z * z) + rc
                        + s * math.sqrt(cx * cx + cy * cy + cz * cz) + t_norm)
    if z + rc < near - slack:
        return 0
    accept = sph[k, 5] != 0.0 and z - rc > near + slack
    for axis in range(2):
        c = x if axis == 0 else y
        hi, lo, n_hi, n_lo = sides[axis, 0], sides[axis, 1], sides[axis, 2], sides[axis, 3]
        a_hi, a_lo, h_hi, h_lo = sides[axis, 4], sides[axis, 5], sides[axis, 6], sides[axis, 7]
        if c - a_hi * z - rc * h_hi > n_hi * reach + slack * h_hi:
            return 0
        if a_lo * z - c - rc * h_lo > n_lo * reach + slack * h_lo:
            return 0
        accept = (accept and (c - hi * z) / n_hi < -(rc + slack)
                  and (lo * z - c) / n_lo < -(rc + slack))
    return 1 if accept else 2


@numba.njit(inline="always", fastmath=False)
def _peak_bound(u, v, d, max_scale, opacity, peak):
    """:func:`splatgl.order.cull.peak_alpha_bound` (perspective, no antialiasing) of one splat at
    camera-space float32 ``(u, v, d)``, d > 0; ``peak`` = fx, fy, cx, cy, width, height, the
    Jacobian's clamps on x/z and y/z, and the radius scale (float32 in NumPy's product)."""
    fx, fy, px, py = peak[0], peak[1], peak[2], peak[3]
    x, y, z = np.float64(u), np.float64(v), np.float64(d)
    xc = min(max(x / z, -peak[6]), peak[6])
    yc = min(max(y / z, -peak[7]), peak[7])
    jf2 = (fx * fx * (1 + xc * xc) + fy * fy * (1 + yc * yc)) / (z * z)
    pu, pv = fx * x / z + px, fy * y / z + py
    ms = np.float64(max_scale * np.float32(peak[8]))
    lam = jf2 * ms * ms + LOW_PASS
    nu = min(max(np.rint(pu - 0.5), 0.0), peak[4] - 1) + 0.5
    nv = min(max(np.rint(pv - 0.5), 0.0), peak[5] - 1) + 0.5
    d2 = (pu - nu) ** 2 + (pv - nv) ** 2
    return np.float64(opacity) * math.exp(-0.5 * d2 / lam)


@numba.njit(inline="always")
def _rigid(rot, trans):
    """The camera's float32 rotation rows and translation as one tuple (r00 .. r22, t0, t1, t2)."""
    return (rot[0, 0], rot[0, 1], rot[0, 2], rot[1, 0], rot[1, 1], rot[1, 2],
            rot[2, 0], rot[2, 1], rot[2, 2], trans[0], trans[1], trans[2])


@numba.njit(inline="always")
def _planes(planes):
    """:func:`splatgl.order.cull.plane_constants` as one tuple (x axis's six, then y's)."""
    return (planes[0, 0], planes[0, 1], planes[0, 2], planes[0, 3], planes[0, 4], planes[0, 5],
            planes[1, 0], planes[1, 1], planes[1, 2], planes[1, 3], planes[1, 4], planes[1, 5])


@numba.njit(inline="always", fastmath=False)
def _row_test(xi, yi, zi, rad, is_faint, max_scale, opacity, rt, pl, near32, peak):
    """:func:`splatgl.order.cull.cull_visible`'s tests of one splat (float32, its operations in its
    order; the peak bound in float64): ``(status, u, v, d)`` with status 0 culled, 1 kept, 2
    kept or culled by a peak bound within :data:`PEAK_UNSURE` of 1/255 (NumPy decides), and
    ``(u, v, d)`` its camera-space point."""
    d = _axis(xi, yi, zi, rt[6], rt[7], rt[8], rt[11])
    if not d > near32:
        return 0, d, d, d
    u = _axis(xi, yi, zi, rt[0], rt[1], rt[2], rt[9])
    if not _between_planes(u, d, rad, pl[0], pl[1], pl[2], pl[3]):
        return 0, u, u, d
    v = _axis(xi, yi, zi, rt[3], rt[4], rt[5], rt[10])
    if not _between_planes(v, d, rad, pl[6], pl[7], pl[8], pl[9]):
        return 0, u, v, d
    inside = u <= d * pl[5] and u >= d * pl[4] and v <= d * pl[11] and v >= d * pl[10]
    if inside and not is_faint:
        return 1, u, v, d
    bound = _peak_bound(u, v, d, max_scale, opacity, peak)
    if bound < ALPHA_MIN * (1.0 - PEAK_UNSURE):
        return 0, u, v, d
    if bound <= ALPHA_MIN * (1.0 + PEAK_UNSURE):  # a NaN bound is kept, as NumPy keeps it
        return 2, u, v, d
    return 1, u, v, d


@numba.njit(inline="always")
def _note_unsure(unsure_rows, unsure_p, c, row, u, v, d):
    """Record undecided row ``c`` (while there is room; counted past it); returns ``c + 1``."""
    if c < unsure_rows.size:
        unsure_rows[c] = row
        unsure_p[c, 0] = u
        unsure_p[c, 1] = v
        unsure_p[c, 2] = d
    return c + 1


@numba.njit(inline="always")
def _cull_row(x, y, z, radius, faint, max_scale, opacity, i, key_index, note_as, rt, pl, near32,
              peak, keys_u32, keys_f32, n, unsure_rows, unsure_p, c):
    """:func:`_row_test` of row ``i``: kept, its key (with ``key_index``) written at ``n``;
    undecided, noted as ``note_as``.  Returns the new ``(n, c)``."""
    status, u, v, d = _row_test(x[i], y[i], z[i], radius[i], faint[i], max_scale[i], opacity[i],
                                rt, pl, near32, peak)
    if status == 1:
        keys_u32[2 * n] = key_index
        keys_f32[2 * n + 1] = d
        n += 1
    elif status == 2:
        c = _note_unsure(unsure_rows, unsure_p, c, note_as, u, v, d)
    return n, c


@numba.njit(cache=True, nogil=True, fastmath=False, boundscheck=False)
def rows_pass(rows, x, y, z, radius, alive, faint, max_scale, opacity, rot, trans, planes,
              near32, peak, keys_u32, keys_f32, unsure_rows, unsure_p):
    """The cull of the rows ``rows`` of a :class:`splatgl.order.cull.CullData` (its arrays as given)
    without gathering them: each alive row takes :func:`_row_test`; kept rows' keys are written
    as :func:`view_pass` writes them, with the row itself as the index; undecided rows go to
    ``unsure_rows`` (as positions in ``rows``) / ``unsure_p``.  Returns (keys, unsure)."""
    rt = _rigid(rot, trans)
    pl = _planes(planes)
    n = 0
    c = 0
    for j in range(rows.size):
        i = rows[j]
        if not alive[i]:
            continue
        n, c = _cull_row(x, y, z, radius, faint, max_scale, opacity, i, i, j, rt, pl, near32,
                         peak, keys_u32, keys_f32, n, unsure_rows, unsure_p, c)
    return n, c


@numba.njit(cache=True, nogil=True, fastmath=False, boundscheck=False)
def view_pass(g0, g1, out0, groups, chunks, group, x, y, z, radius, faint, max_scale, opacity,
              index, starts, rot64, trans64, view, sides, rot, trans, planes, near32, peak,
              keys_u32, keys_f32, unsure_rows, unsure_p):
    """A whole pinhole view of the chunked cull in one pass: each group of ``group`` chunks
    classified (:func:`_sphere_class` on ``groups``), a boundary group's chunks one by one
    (on ``chunks``); then per chunk by its class: an accepted chunk's rows take the depth
    only, a tested chunk's rows the near and side-plane tests
    (:func:`splatgl.order.cull.cull_visible`'s float32 operations) and, where the centre projects
    outside the image or the splat is faint, the peak alpha bound.  Kept rows' keys go to
    ``keys_u32[2 n] = index`` and ``keys_f32[2 n + 1] = z`` (two views of the uint64 key
    buffer); rows whose bound is within :data:`PEAK_UNSURE` of 1/255 go to ``unsure_rows`` /
    ``unsure_p`` (up to their size; counted past it).
    Only the groups ``g0:g1`` and their rows, keys written from key ``out0`` on (two calls on
    disjoint group ranges can run at once: it releases the GIL, and a range's keys never
    outnumber its rows, so keys written from its first row stay inside it).
    Returns (keys, unsure)."""
    n_chunks = starts.size - 1
    k0, k1 = g0 * group, min(n_chunks, g1 * group)
    flags = np.zeros(k1 - k0, np.int8)
    for g in range(g0, g1):
        cls = _sphere_class(groups, g, rot64, trans64, view, sides)
        lo, hi = g * group, min(n_chunks, (g + 1) * group)
        for k in range(lo, hi):
            flags[k - k0] = (cls if cls != 2
                             else _sphere_class(chunks, k, rot64, trans64, view, sides))
    rt = _rigid(rot, trans)
    pl = _planes(planes)
    r20, r21, r22, t2 = rt[6], rt[7], rt[8], rt[11]
    n = out0
    c = 0
    for k in range(k0, k1):
        f = flags[k - k0]
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
            n, c = _cull_row(x, y, z, radius, faint, max_scale, opacity, i, index[i], i, rt, pl,
                             near32, peak, keys_u32, keys_f32, n, unsure_rows, unsure_p, c)
    return n - out0, c


@numba.njit(inline="always")
def _note_point(rows, p, c, row, u, v, w, d):
    """Record row ``c`` with its camera-space point and distance (while there is room;
    counted past it); returns ``c + 1``."""
    if c < rows.size:
        rows[c] = row
        p[c, 0] = u
        p[c, 1] = v
        p[c, 2] = w
        p[c, 3] = d
    return c + 1


@numba.njit(cache=True, nogil=True, fastmath=False, boundscheck=False)
def lens_pass(a, b, out0, x, y, z, radius, index, rot, trans, near32, mode, cos_limit, band,
              seam_scale, seam_px, keys_u32, keys_f32, seam_rows, seam_p):
    """:func:`splatgl.order.lens_cull.lens_visible_keys`'s per-row work on the rows ``a:b``, keys
    written from key ``out0`` on (as :func:`view_pass` writes them, distance for depth): the
    distance ``|p|`` beyond the near plane and, with ``mode`` 1 (fisheye), the cone test
    ``z - |p| cos_limit >= 0`` (float32: the decision itself,
    :func:`splatgl.order.lens_cull.cone_keeps`); with ``mode`` 2 (equirectangular) kept rows within the seam bound widened by
    ``band`` (``(radius seam_scale + |p| seam_px) (1 + band)``) go to ``seam_rows`` / ``seam_p``
    (x, y, z, |p|), where NumPy's float32 copy test decides (counted past their size).
    Returns (keys, 0, seam candidates)."""
    rt = _rigid(rot, trans)
    n = out0
    ns = 0
    for i in range(a, b):
        xi, yi, zi = x[i], y[i], z[i]
        u = _axis(xi, yi, zi, rt[0], rt[1], rt[2], rt[9])
        v = _axis(xi, yi, zi, rt[3], rt[4], rt[5], rt[10])
        w = _axis(xi, yi, zi, rt[6], rt[7], rt[8], rt[11])
        d = np.sqrt(u * u + v * v + w * w)
        if not d > near32:
            continue
        if mode == 1:
            off = w - d * cos_limit
            if not off >= np.float32(0):
                continue
        keys_u32[2 * n] = index[i]
        keys_f32[2 * n + 1] = d
        n += 1
        if mode == 2:
            reach = (radius[i] * seam_scale + d * seam_px) * (np.float32(1) + band)
            if abs(u) < reach and w < reach:
                ns = _note_point(seam_rows, seam_p, ns, i, u, v, w, d)
    return n - out0, 0, ns


def warm_up() -> None:
    """Compile (or load from numba's cache) the kernel for the argument types the cull uses."""
    f4, u4 = np.zeros(2, np.float32), np.zeros(2, np.uint32)
    sph = np.zeros((1, 6))
    view_pass(0, 1, 0, sph, sph, 16, f4, f4, f4, f4, np.zeros(2, np.bool_), f4, f4, u4,
              np.array([0, 2], np.int64), np.eye(3), np.zeros(3), np.zeros(5), np.zeros((2, 8)),
              np.eye(3, dtype=np.float32), np.zeros(3, np.float32), np.zeros((2, 6), np.float32),
              np.float32(0.0), np.zeros(9), np.zeros(4, np.uint32), np.zeros(4, np.float32),
              np.zeros(2, np.int64), np.zeros((2, 3), np.float32))
    lens_pass(0, 2, 0, f4, f4, f4, f4, u4, np.eye(3, dtype=np.float32), np.zeros(3, np.float32),
              np.float32(0.0), 1, np.float32(0.5), np.float32(1e-4), np.float32(1.0),
              np.float32(0.01), np.zeros(4, np.uint32), np.zeros(4, np.float32),
              np.zeros(2, np.int64), np.zeros((2, 4), np.float32))
    rows_pass(np.zeros(1, np.int64), f4, f4, f4, f4, np.ones(2, np.bool_), np.zeros(2, np.bool_),
              f4, f4, np.eye(3, dtype=np.float32), np.zeros(3, np.float32),
              np.zeros((2, 6), np.float32), np.float32(0.0), np.zeros(9), np.zeros(4, np.uint32),
              np.zeros(4, np.float32), np.zeros(2, np.int64), np.zeros((2, 3), np.float32))
