"""The CPU renderer's compiled stage 1 (numba, the ``fast`` extra); imported only by
:mod:`splatgl.renderers.cpu`, which keeps numba optional.

- :func:`project_pinhole`: the reference's stage 1 for a pinhole camera (INRIA rules) per splat,
  in parallel: the same float32 formulas as :mod:`splatgl.splatmath.project` (camera space, the
  clamped EWA Jacobian, the dilated covariance with the cancellation guard on its determinant,
  the conic, antialiasing, ``ceil(3 sqrt(lambda_max))`` and 3DGS's ``getRect``, the SH colour).
  The order of a few float32 operations differs from NumPy's, so its numbers agree with the
  twin to a few ulps, not bit for bit (tests/renderers/test_cpu_renderer.py).
- :func:`project_model`: the same for any other camera model, from the points, Jacobians and
  culling its NumPy methods computed (:meth:`splatgl.renderers._cpu_stage1.Stage1.model`).
  Both share :func:`_finish`, everything after the Jacobian.

Each splat also gets its pixel box: the bounding box of the ellipse where ``o exp(-q/2) >=
1/255`` (the only pixels where the reference blends it) plus :data:`BOX_MARGIN`, and its tile
rectangle is cut to the tiles of that box.  :mod:`._cpu_raster` evaluates only the box.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from ..constants import (AA_MIN_FACTOR, DET_CANCEL_RATIO, EXTENT_DISCRIMINANT_FLOOR,
                         EXTENT_SIGMAS, MAX_RADIUS, SH_C0, SH_C1, SH_C2, SH_C3, SH_OFFSET,
                         TILE_SIZE)

#: Pixels added on every side of a splat's box: the box is computed in float64 from the
#: float32 conic, and the exp below differs from the reference's in the last bits, so a pixel
#: the reference blends at exactly 1/255 stays inside.
BOX_MARGIN = 1.0

_F = np.float32


@numba.njit(inline="always", fastmath=False)
def _floor(x):
    """``floor(x)`` as a float, for x clamped to +-1e15 first (every use clamps the result to
    the tile grid, far inside that; the clamp keeps the integer conversion defined)."""
    return float(math.floor(min(max(x, -1e15), 1e15)))


@numba.njit(inline="always", fastmath=False)
def _ceil(x):
    """``ceil(x)`` as a float, x clamped as in :func:`_floor`."""
    return float(math.ceil(min(max(x, -1e15), 1e15)))


@numba.njit(inline="always", fastmath=False)
def _trunc(x):
    """C's float-to-integer truncation (3DGS's ``(int)``) as a float, x clamped as in :func:`_floor`."""
    return _floor(x) if x >= 0 else -_floor(-x)


@numba.njit(inline="always", fastmath=False)
def _cut_to_box(u, v, qa, qb, qc, q2, tx0, tx1, ty0, ty1, x_end, y_end):
    """The pixel box ``[bx0, bx1) x [by0, by1)`` of the ellipse ``q <= q2`` of the conic
    (qa, qb, qc) around (u, v), in float64, :data:`BOX_MARGIN` wider on every side, its ends
    clamped to -1 and ``x_end``, ``y_end`` (integers as floats stay exact), and the tile
    rectangle ``[tx0, tx1) x [ty0, ty1)`` cut to the box's tiles.  A conic without a usable
    determinant keeps the whole rectangle as its box."""
    qdet = qa * qc - qb * qb
    if not (qdet > 0 and math.isfinite(qdet)):
        return (tx0 * TILE_SIZE, tx1 * TILE_SIZE, ty0 * TILE_SIZE, ty1 * TILE_SIZE,
                tx0, tx1, ty0, ty1)
    hx = math.sqrt(q2 * qc / qdet) + BOX_MARGIN
    hy = math.sqrt(q2 * qa / qdet) + BOX_MARGIN
    bx0 = max(_ceil(u - 0.5 - hx), -1.0)
    bx1 = min(_floor(u - 0.5 + hx) + 1.0, x_end)
    by0 = max(_ceil(v - 0.5 - hy), -1.0)
    by1 = min(_floor(v - 0.5 + hy) + 1.0, y_end)
    return (bx0, bx1, by0, by1, max(tx0, _floor(bx0 / TILE_SIZE)),
            min(tx1, _floor((bx1 - 1.0) / TILE_SIZE) + 1.0), max(ty0, _floor(by0 / TILE_SIZE)),
            min(ty1, _floor((by1 - 1.0) / TILE_SIZE) + 1.0))


@numba.njit(inline="always", fastmath=False)
def _sh_color(sh, i, k, x, y, z):
    """``max(sum h_lm Y_lm(d) + 0.5, 0)`` of splat ``i``'s first ``k`` coefficients at the unit
    direction (x, y, z) (:func:`splatgl.splatmath.project.sh_basis`'s trig-free form), as 3 floats."""
    r = _F(SH_C0) * sh[i, 0, 0]
    g = _F(SH_C0) * sh[i, 0, 1]
    b = _F(SH_C0) * sh[i, 0, 2]
    if k > 1:
        for j, y_lm in ((1, -_F(SH_C1) * y), (2, _F(SH_C1) * z), (3, -_F(SH_C1) * x)):
            r += y_lm * sh[i, j, 0]
            g += y_lm * sh[i, j, 1]
            b += y_lm * sh[i, j, 2]
    if k > 4:
        xx, yy, zz, xy, yz, xz = x * x, y * y, z * z, x * y, y * z, x * z
        for j, y_lm in ((4, _F(SH_C2[0]) * xy), (5, _F(SH_C2[1]) * yz),
                        (6, _F(SH_C2[2]) * (_F(2) * zz - xx - yy)), (7, _F(SH_C2[3]) * xz),
                        (8, _F(SH_C2[4]) * (xx - yy))):
            r += y_lm * sh[i, j, 0]
            g += y_lm * sh[i, j, 1]
            b += y_lm * sh[i, j, 2]
        if k > 9:
            for j, y_lm in ((9, _F(SH_C3[0]) * y * (_F(3) * xx - yy)),
                            (10, _F(SH_C3[1]) * xy * z),
                            (11, _F(SH_C3[2]) * y * (_F(4) * zz - xx - yy)),
                            (12, _F(SH_C3[3]) * z * (_F(2) * zz - _F(3) * xx - _F(3) * yy)),
                            (13, _F(SH_C3[4]) * x * (_F(4) * zz - xx - yy)),
                            (14, _F(SH_C3[5]) * z * (xx - yy)),
                            (15, _F(SH_C3[6]) * x * (xx - _F(3) * yy))):
                r += y_lm * sh[i, j, 0]
                g += y_lm * sh[i, j, 1]
                b += y_lm * sh[i, j, 2]
    return (max(r + _F(SH_OFFSET), _F(0.0)), max(g + _F(SH_OFFSET), _F(0.0)),
            max(b + _F(SH_OFFSET), _F(0.0)))


@numba.njit(inline="always", fastmath=False)
def _finish(i, o_, x0, y0, z0, u, v, t0, t1, rs, opacity, sh, k, center, lp, antialias, grid_x,
            grid_y, mean2d, conic, opac_out, reach, color, box, rect):
    """Input row ``i`` of stage 1, written to output row ``o_``, from its pixel position
    (u, v) and ``T = J W`` (rows ``t0``, ``t1``: the model's EWA Jacobian times the view
    rotation), for every camera model: the dilated
    covariance ``M M^T + lp I`` with ``M = T R S``, the guarded determinant, the conic,
    antialiasing, the reference's radius and rectangle, the SH colour seen from ``center``
    (``x0, y0, z0`` is the anchored mean) and the pixel box.  A culled row keeps its empty
    ``rect``."""
    # M = T R S (2x3); the screen covariance is M M^T + low_pass I
    m0 = (t0[0] * rs[i, 0, 0] + t0[1] * rs[i, 1, 0] + t0[2] * rs[i, 2, 0],
          t0[0] * rs[i, 0, 1] + t0[1] * rs[i, 1, 1] + t0[2] * rs[i, 2, 1],
          t0[0] * rs[i, 0, 2] + t0[1] * rs[i, 1, 2] + t0[2] * rs[i, 2, 2])
    m1 = (t1[0] * rs[i, 0, 0] + t1[1] * rs[i, 1, 0] + t1[2] * rs[i, 2, 0],
          t1[0] * rs[i, 0, 1] + t1[1] * rs[i, 1, 1] + t1[2] * rs[i, 2, 1],
          t1[0] * rs[i, 0, 2] + t1[1] * rs[i, 1, 2] + t1[2] * rs[i, 2, 2])
    a = m0[0] * m0[0] + m0[1] * m0[1] + m0[2] * m0[2] + lp
    b = m0[0] * m1[0] + m0[1] * m1[1] + m0[2] * m1[2]
    c_ = m1[0] * m1[0] + m1[1] * m1[1] + m1[2] * m1[2] + lp
    plain = a * c_ - b * b
    if plain > _F(DET_CANCEL_RATIO) * (a * c_):
        det = plain
    else:   # Cauchy-Binet: the sum of M's squared 2x2 minors, never cancelled to <= 0
        cx_ = m0[1] * m1[2] - m0[2] * m1[1]
        cy_ = m0[2] * m1[0] - m0[0] * m1[2]
        cz_ = m0[0] * m1[1] - m0[1] * m1[0]
        trace = (m0[0] * m0[0] + m0[1] * m0[1] + m0[2] * m0[2]) + (
            m1[0] * m1[0] + m1[1] * m1[1] + m1[2] * m1[2])
        det = (cx_ * cx_ + cy_ * cy_ + cz_ * cz_) + lp * trace + lp * lp
    if not det > 0:
        return
    inv = _F(1.0) / det
    qa, qb, qc = c_ * inv, -b * inv, a * inv
    o = opacity[i]
    if antialias:
        undilated = (a - lp) * (c_ - lp) - b * b
        ratio = undilated / plain if plain > 0 else _F(0.0)
        o = o * math.sqrt(max(_F(AA_MIN_FACTOR), ratio))
    # the reference's radius and tile rectangle (3DGS getRect, p = mean2d - 0.5)
    mid = _F(0.5) * (a + c_)
    disc = mid * mid - plain
    if not math.isfinite(disc):
        half = _F(0.5) * (a - c_)
        disc = half * half + b * b
    lam = mid + math.sqrt(max(_F(EXTENT_DISCRIMINANT_FLOOR), disc))
    r = _F(EXTENT_SIGMAS) * math.sqrt(max(lam, _F(0.0)))
    r = float(math.ceil(min(r, MAX_RADIUS))) if math.isfinite(r) else MAX_RADIUS
    # direction for the SH colour: the splat from the camera centre
    dx, dy, dz = x0 - center[0], y0 - center[1], z0 - center[2]
    n = math.sqrt(dx * dx + dy * dy + dz * dz)
    if n > 0:
        dx, dy, dz = dx / n, dy / n, dz / n
    cr, cg, cb = _sh_color(sh, i, k, dx, dy, dz)
    if not (math.isfinite(u) and math.isfinite(v) and math.isfinite(qa) and math.isfinite(qb)
            and math.isfinite(qc) and math.isfinite(o) and math.isfinite(cr)
            and math.isfinite(cg) and math.isfinite(cb)):
        return
    rf = _F(r)
    px, py = u - _F(0.5), v - _F(0.5)
    tx0 = min(max(_trunc((px - rf) / _F(TILE_SIZE)), 0.0), grid_x)
    ty0 = min(max(_trunc((py - rf) / _F(TILE_SIZE)), 0.0), grid_y)
    tx1 = min(max(_trunc((px + rf + _F(TILE_SIZE - 1)) / _F(TILE_SIZE)), 0.0), grid_x)
    ty1 = min(max(_trunc((py + rf + _F(TILE_SIZE - 1)) / _F(TILE_SIZE)), 0.0), grid_y)
    if float(o) * 255.0 <= 1.0:
        return
    q2 = 2.0 * math.log(float(o) * 255.0)
    bx0, bx1, by0, by1, tx0, tx1, ty0, ty1 = _cut_to_box(
        float(u), float(v), float(qa), float(qb), float(qc), q2, tx0, tx1, ty0, ty1,
        grid_x * TILE_SIZE + 1.0, grid_y * TILE_SIZE + 1.0)
    if not (tx1 > tx0 and ty1 > ty0):
        return
    mean2d[o_, 0], mean2d[o_, 1] = u, v
    conic[o_, 0], conic[o_, 1], conic[o_, 2] = qa, qb, qc
    opac_out[o_] = o
    reach[o_] = q2
    color[o_, 0], color[o_, 1], color[o_, 2] = cr, cg, cb
    box[o_, 0], box[o_, 1], box[o_, 2], box[o_, 3] = int(bx0), int(bx1), int(by0), int(by1)
    rect[o_, 0], rect[o_, 1], rect[o_, 2], rect[o_, 3] = int(tx0), int(tx1), int(ty0), int(ty1)


@numba.njit(parallel=True, fastmath=False, cache=True)
def project_pinhole(rel, rs, opacity, sh, rows, k, cam, center, grid_x, grid_y, antialias,
                    mean2d, conic, opac_out, reach, color, depth, box, rect):
    """Project the splats ``rows`` (int64 indices into the inputs; output row j is input row
    ``rows[j]``) for a pinhole camera; culled rows get an empty ``rect``.

    Inputs (float32 unless said): ``rel`` (N, 3) means minus the view's anchor; ``rs`` (N, 3, 3)
    ``R S`` (rotation times scales, per column); ``opacity`` (N,); ``sh`` (N, K, 3), ``k`` the
    coefficients used; ``cam`` (20,) float64: the anchored world-to-camera rotation (9,
    row-major), translation (3), fx, fy, cx, cy, the Jacobian's x/z and y/z limits, the near
    plane and the low pass; ``center`` (3,) the anchored camera centre; the tile grid; whether
    to antialias.  Outputs (one row per entry of ``rows``): ``mean2d`` (2), ``conic`` (3),
    ``opac_out``, ``reach`` (``2 ln(255 o)``, the conic value where alpha falls to 1/255),
    ``color`` (3), ``depth`` (view z), ``box`` (4) int32 pixel box ``[x0, x1) x [y0, y1)`` and
    ``rect`` (4) int32 tile rectangle ``[tx0, tx1) x [ty0, ty1)``: the reference's ``getRect``
    of its radius, shrunk to the tiles the box touches.
    """
    w = cam[:9].astype(np.float32)
    t = cam[9:12].astype(np.float32)
    fx, fy, cx, cy = _F(cam[12]), _F(cam[13]), _F(cam[14]), _F(cam[15])
    limx, limy, near, lp = _F(cam[16]), _F(cam[17]), _F(cam[18]), _F(cam[19])
    for j in numba.prange(rows.shape[0]):
        i = rows[j]
        rect[j, 0] = 0
        rect[j, 1] = 0
        rect[j, 2] = 0
        rect[j, 3] = 0
        x0, y0, z0 = rel[i, 0], rel[i, 1], rel[i, 2]
        x = ((x0 * w[0] + y0 * w[1]) + z0 * w[2]) + t[0]
        y = ((x0 * w[3] + y0 * w[4]) + z0 * w[5]) + t[1]
        z = ((x0 * w[6] + y0 * w[7]) + z0 * w[8]) + t[2]
        depth[j] = z
        if not z > near:
            continue
        u = fx * x / z + cx
        v = fy * y / z + cy
        # EWA Jacobian (x/z and y/z clamped inside it only), times the view rotation: T = J W
        xz = min(max(x / z, -limx), limx)
        yz = min(max(y / z, -limy), limy)
        j00 = fx / z
        j02 = -fx * xz / z
        j11 = fy / z
        j12 = -fy * yz / z
        t0 = (j00 * w[0], j00 * w[1], j00 * w[2])
        t1 = (j11 * w[3] + j12 * w[6], j11 * w[4] + j12 * w[7], j11 * w[5] + j12 * w[8])
        t0 = (t0[0] + j02 * w[6], t0[1] + j02 * w[7], t0[2] + j02 * w[8])
        _finish(i, j, x0, y0, z0, u, v, t0, t1, rs, opacity, sh, k, center, lp, antialias,
                grid_x, grid_y, mean2d, conic, opac_out, reach, color, box, rect)


@numba.njit(parallel=True, fastmath=False, cache=True)
def project_model(rel, rs, opacity, sh, k, cam, center, grid_x, grid_y, antialias, uv, jac,
                  visible, mean2d, conic, opac_out, reach, color, box, rect):
    """:func:`project_pinhole` for any camera model without a seam, from what the model's
    NumPy methods computed: ``uv`` (N, 2) pixel positions, ``jac`` (N, 2, 3) EWA Jacobians
    and ``visible`` (N,) its culling rule.  ``cam`` (10,) float64: the anchored world-to-camera
    rotation (9, row-major) and the low pass; the rest as there (the depth is the model's,
    filled by the caller)."""
    w = cam[:9].astype(np.float32)
    lp = _F(cam[9])
    for i in numba.prange(rel.shape[0]):
        rect[i, 0] = 0
        rect[i, 1] = 0
        rect[i, 2] = 0
        rect[i, 3] = 0
        if not visible[i]:
            continue
        t0 = ((jac[i, 0, 0] * w[0] + jac[i, 0, 1] * w[3]) + jac[i, 0, 2] * w[6],
              (jac[i, 0, 0] * w[1] + jac[i, 0, 1] * w[4]) + jac[i, 0, 2] * w[7],
              (jac[i, 0, 0] * w[2] + jac[i, 0, 1] * w[5]) + jac[i, 0, 2] * w[8])
        t1 = ((jac[i, 1, 0] * w[0] + jac[i, 1, 1] * w[3]) + jac[i, 1, 2] * w[6],
              (jac[i, 1, 0] * w[1] + jac[i, 1, 1] * w[4]) + jac[i, 1, 2] * w[7],
              (jac[i, 1, 0] * w[2] + jac[i, 1, 1] * w[5]) + jac[i, 1, 2] * w[8])
        _finish(i, i, rel[i, 0], rel[i, 1], rel[i, 2], uv[i, 0], uv[i, 1], t0, t1, rs, opacity, sh,
                k, center, lp, antialias, grid_x, grid_y, mean2d, conic, opac_out, reach, color,
                box, rect)
