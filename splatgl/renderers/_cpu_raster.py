"""The CPU renderer's compiled stages 2-5 (numba, the ``fast`` extra); imported only by
:mod:`splatgl.renderers.cpu`, which keeps numba optional.

- :func:`pack`: the drawn splats' records in depth order, one cache line each.
- :func:`bin_tiles`: every drawn splat appended to the list of each tile its rectangle touches,
  in depth order (a stable counting sort by tile: no key sort).
- :func:`rasterize`: the reference's stage 5 per 16x16 tile, tiles in parallel.

Where the time goes: the reference evaluates all 256 pixels of a tile for each splat in its
list; here only the pixels of each row of the splat's box where its alpha can reach 1/255 (the
row's span of the ellipse, widened to whole blocks of 8).  The inner loop is written so that
LLVM vectorises it: unsigned indices, selects instead of branches, an exp of its own
(:func:`_exp`), fused multiply-adds allowed (``fastmath={"contract"}``).  Measured on the
flight's views at 1280x720 (docs/interactive.md): each of those took 10-30% off the frame.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from ..constants import ALPHA_MAX, ALPHA_MIN, T_MIN, TILE_SIZE
from ._cpu_project import BOX_MARGIN, _ceil, _floor

#: Pixels of a tile row blended as one vector (AVX2: 8 float32).
BLOCK = 8
#: Powers below this are treated as this (``exp(-12) o < 1/255`` for any opacity <= 1).
POWER_FLOOR = -12.0
_F = np.float32
_ALPHA_MIN = _F(ALPHA_MIN)
_ALPHA_MAX = _F(ALPHA_MAX)
_T_MIN = _F(T_MIN)


@numba.njit(inline="always", fastmath=False)
def _exp(x):
    """``exp(x)`` for float32 ``x`` in [POWER_FLOOR, 0]: ``exp(x / 16) ** 16`` with a degree-7
    Taylor polynomial on [-0.75, 0].  Relative error below 3e-6 where a splat can blend
    (``x >= ln(1/255)``), below 1e-4 down to the floor (tested against ``np.exp``).  LLVM
    vectorises it, where a call to the C library's ``expf`` keeps the loop scalar."""
    r = x * _F(0.0625)
    p = _F(1.0 / 5040.0)
    p = p * r + _F(1.0 / 720.0)
    p = p * r + _F(1.0 / 120.0)
    p = p * r + _F(1.0 / 24.0)
    p = p * r + _F(1.0 / 6.0)
    p = p * r + _F(0.5)
    p = p * r + _F(1.0)
    p = p * r + _F(1.0)
    p = p * p
    p = p * p
    p = p * p
    return p * p

#: Fields of a splat's record in :func:`pack`'s table (16 float32: one cache line).
REC_MX, REC_MY, REC_A, REC_B, REC_C, REC_O, REC_REACH, REC_R, REC_G, REC_BL, REC_Z = range(11)
REC_BOX = 11        # 4 fields: the pixel box x0, x1, y0, y1 (integers held exactly as floats)
REC_SIZE = 16


@numba.njit(parallel=True, fastmath=False, cache=True)
def pack(order, mean2d, conic, opacity, reach, color, depth, box, out):
    """Fill ``out`` ((len(order), REC_SIZE) float32) with each drawn splat's record, in
    ``order`` (front to back), so that the rasterizer reads one cache line per splat, in
    increasing address.  Slices of ``order`` and ``out`` pack a part."""
    for k in numba.prange(order.shape[0]):
        i = order[k]
        out[k, REC_MX] = mean2d[i, 0]
        out[k, REC_MY] = mean2d[i, 1]
        out[k, REC_A] = conic[i, 0]
        out[k, REC_B] = conic[i, 1]
        out[k, REC_C] = conic[i, 2]
        out[k, REC_O] = opacity[i]
        out[k, REC_REACH] = reach[i]
        out[k, REC_R] = color[i, 0]
        out[k, REC_G] = color[i, 1]
        out[k, REC_BL] = color[i, 2]
        out[k, REC_Z] = depth[i]
        for c in range(4):
            out[k, REC_BOX + c] = box[i, c]


@numba.njit(parallel=True, fastmath=False, cache=True)
def bin_tiles(order, rect, grid_x, n_tiles, parts):
    """Tile lists: ``(starts (n_tiles + 1,) int64, rows (M,) int32)``, tile ``t``'s splats being
    ``rows[starts[t]:starts[t + 1]]``, positions in ``order`` (front to back; :func:`pack` lays
    the splats out in that order, so a tile reads its splats' records in increasing address).
    The same lists as the reference's sorted keys, which order a tile's splats by depth, then
    index.  A counting sort by tile, stable and in parallel: ``order`` is cut into ``parts``
    runs, each counted and then filled by one thread at its own offsets."""
    m = order.shape[0]
    counts = np.zeros((parts, n_tiles), np.int64)
    for p in numba.prange(parts):
        for k in range(m * p // parts, m * (p + 1) // parts):
            i = order[k]
            for ty in range(rect[i, 2], rect[i, 3]):
                for tx in range(rect[i, 0], rect[i, 1]):
                    counts[p, ty * grid_x + tx] += 1
    starts = np.zeros(n_tiles + 1, np.int64)
    fill = np.empty((parts, n_tiles), np.int64)
    run = 0
    for t in range(n_tiles):
        starts[t] = run
        for p in range(parts):
            fill[p, t] = run
            run += counts[p, t]
    starts[n_tiles] = run
    rows = np.empty(run, np.int32)
    for p in numba.prange(parts):
        for k in range(m * p // parts, m * (p + 1) // parts):
            i = order[k]
            for ty in range(rect[i, 2], rect[i, 3]):
                for tx in range(rect[i, 0], rect[i, 1]):
                    t = ty * grid_x + tx
                    rows[fill[p, t]] = k
                    fill[p, t] += 1
    return starts, rows


@numba.njit(inline="always", fastmath=False, boundscheck=False)
def _blend_row(acc_r, acc_g, acc_b, acc_z, trans, lo, n, first, last, dx0, qa, cdy, bdy, o, cr,
               cg, cb, z):
    """Blend one splat into the ``n`` pixels of a tile row from pixel ``lo`` (uint64), of which
    those at offsets ``first <= jj < last`` are in its span; the others take alpha 0 and are
    left as they are.  The caller widens spans to whole blocks of 8 (:data:`BLOCK`) so that the
    loop runs as whole AVX2 vectors, with no scalar remainder for short spans.

    Per pixel of the tile: the colour and depth sums and T, stored negated once the pixel has
    stopped.  The reference's rule: ``alpha = min(0.99, o exp(power))``, skipped when
    ``alpha < 1/255``; stop (without adding) once ``T (1 - alpha) < 1e-4``.  A stopped pixel
    (T < 0) takes alpha 0, so ``T (1 - 0) < 1e-4`` keeps it stopped and adds nothing.

    The reference also skips ``power > 0``.  The conic is positive definite (the projection
    culls a covariance without a positive determinant), so a positive power is rounding: it
    counts as 0 here.  Along the axis of a needle whose conic cancels (stress case
    det_nonpositive) the power is 0 up to rounding, and this loop's own order of operations
    (fused multiply-adds) made it 1 ulp positive on two pixels, which lost the needle there
    (error 0.252 against the float64 truth; the reference's float32 order happens to land on
    0).  Clamping keeps the truth's value wherever the reference draws the pixel.
    """
    for jj in range(n):
        j = lo + jj
        dx = dx0 + _F(jj)
        power = min(qa * dx * dx + cdy - bdy * dx, _F(0.0))
        alpha = min(_ALPHA_MAX, o * _exp(max(power, _F(POWER_FLOOR))))
        tp = trans[j]
        ok = (alpha >= _ALPHA_MIN) & (tp > _F(0.0)) & (jj >= first) & (jj < last)
        alpha = alpha if ok else _F(0.0)
        tn = tp * (_F(1.0) - alpha)
        stop = tn < _T_MIN
        wgt = _F(0.0) if stop else alpha * tp
        acc_r[j] += cr * wgt
        acc_g[j] += cg * wgt
        acc_b[j] += cb * wgt
        acc_z[j] += z * wgt
        trans[j] = -abs(tp) if stop else tn


@numba.njit(parallel=True, fastmath={"contract"}, cache=True, boundscheck=False)
def rasterize(starts, rows, tiles, rec, grid_x, rgba, depth_out, with_depth):
    """Blend every tile's list front to back into ``rgba`` (H, W, 4) (premultiplied: ``C`` and
    ``1 - T``; the caller composites a background) and, ``with_depth``, ``depth_out`` (H, W)
    (``sum z alpha T``).  ``tiles``: the tile ids in the order the
    threads share them (interleaved, so that each thread gets near and far, full and empty
    tiles alike).  ``rec``: :func:`pack`'s records; each row of a splat's box is cut to the
    span where the conic's ``q <= reach`` (``2 ln(255 o)``, where alpha falls to 1/255; plus
    the box margin), solved in float64."""
    height, width = rgba.shape[0], rgba.shape[1]
    tile = TILE_SIZE
    for s in numba.prange(tiles.shape[0]):
        t = tiles[s]
        x0 = (t % grid_x) * tile
        y0 = (t // grid_x) * tile
        acc_r = np.zeros(tile * tile, np.float32)
        acc_g = np.zeros(tile * tile, np.float32)
        acc_b = np.zeros(tile * tile, np.float32)
        acc_z = np.zeros(tile * tile, np.float32)
        trans = np.ones(tile * tile, np.float32)
        for k in range(starts[t], starts[t + 1]):
            j = rows[k]
            xa = max(int(rec[j, REC_BOX]) - x0, 0)
            xb = min(int(rec[j, REC_BOX + 1]) - x0, tile)
            ya = max(int(rec[j, REC_BOX + 2]) - y0, 0)
            yb = min(int(rec[j, REC_BOX + 3]) - y0, tile)
            if xb > xa:
                mx, my = rec[j, REC_MX], rec[j, REC_MY]
                ca, cb_, cc = float(rec[j, REC_A]), float(rec[j, REC_B]), float(rec[j, REC_C])
                qa, qb, qc = _F(-0.5) * rec[j, REC_A], rec[j, REC_B], _F(-0.5) * rec[j, REC_C]
                # each row's span: a dx^2 + 2 b dx dy + c dy^2 <= reach, solved for dx:
                # dx = (-b dy +- sqrt(a reach - det dy^2)) / a; rows beside the ellipse get
                # its nearest pixels (the margin)
                spans = ca > 0.0
                inv_a = 1.0 / ca if spans else 0.0
                a_reach = ca * float(rec[j, REC_REACH])
                det = ca * cc - cb_ * cb_
                mid0 = float(mx) - 0.5 - x0
                for py in range(ya, yb):
                    dy = _F(y0 + py) + _F(0.5) - my
                    ra, rb = xa, xb
                    if spans:
                        dyd = float(dy)
                        half = math.sqrt(max(a_reach - det * dyd * dyd, 0.0)) * inv_a + BOX_MARGIN
                        mid = mid0 - cb_ * dyd * inv_a
                        if math.isfinite(mid) and math.isfinite(half):
                            ra = max(ra, int(_ceil(mid - half)))
                            rb = min(rb, int(_floor(mid + half)) + 1)
                    if rb <= ra:
                        continue
                    lo = ra - ra % BLOCK
                    n = (rb - lo + BLOCK - 1) // BLOCK * BLOCK
                    _blend_row(acc_r, acc_g, acc_b, acc_z, trans, np.uint64(py * tile + lo),
                               np.uint64(n), np.uint64(ra - lo), np.uint64(rb - lo),
                               _F(x0 + lo) + _F(0.5) - mx, qa, qc * dy * dy, qb * dy,
                               rec[j, REC_O], rec[j, REC_R], rec[j, REC_G], rec[j, REC_BL],
                               rec[j, REC_Z])
            if (k - starts[t]) % 32 == 31:     # every pixel stopped: the rest cannot blend
                alive = 0
                for p in range(tile * tile):
                    alive += trans[p] > _F(0.0)
                if alive == 0:
                    break
        for p in range(tile * tile):
            y = y0 + p // tile
            x = x0 + p % tile
            if y < height and x < width:
                tf = abs(trans[p])
                rgba[y, x, 0] = acc_r[p]
                rgba[y, x, 1] = acc_g[p]
                rgba[y, x, 2] = acc_b[p]
                rgba[y, x, 3] = _F(1.0) - tf
                if with_depth:
                    depth_out[y, x] = acc_z[p]
