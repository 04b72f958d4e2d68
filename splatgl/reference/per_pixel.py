"""The per-pixel order of the reference (``--order per-pixel``): each pixel blends its splats
sorted by the depth at which each splat's Gaussian peaks along that pixel's ray (StopThePop,
Radl et al. 2024), instead of the global order of the splats' centres.

Peak depth.  Along the ray ``o + t d`` of a pixel, a 3D Gaussian of camera-space mean ``mu`` and
covariance ``Sigma`` peaks at ``t* = d^T Q (mu - o) / (d^T Q d)``, ``Q = Sigma^-1``.  With the
camera's rays ``d = (a_x, a_y, 1)`` (perspective: ``a = ((x - cx) / fx, (y - cy) / fy)``, o = 0)
``t*`` is the view z of the peak.  Written about the ray through the centre, ``m = mu / mu_z``,
``delta = a - m``, it is

    t* = mu_z (A + B . delta) / (A + 2 B . delta + delta^T Q2 delta)

with ``A = m^T Q m``, ``B = (Q m)_xy``, ``Q2`` the xy block of Q: well conditioned near the
splat, and ``t* = mu_z`` on the centre's ray.  Orthographic (o = (a, 0), d = (0, 0, 1),
``a = (x - cx) / fx`` ...): ``t* = mu_z + B . delta`` with ``delta = a - mu_xy`` and
``B = -(Q_zx, Q_zy) / Q_zz``.  Q is scaled by the smallest squared scale (``t*`` does not change),
so flat splats keep finite coefficients.  ``t*`` is clamped to the splat's 3-sigma range of view
depth, ``mu_z +- 3 sqrt(Sigma_zz)`` (:data:`splatgl.splatmath.peak.PEAK_CLAMP_SIGMAS`): along a ray
nearly parallel to a needle or a flat splat the unclamped peak lies far outside it.  2DGS surfels sort by the view z of the ray's hit, which
the surfel branch already computes.  The depth layer accumulates the same per-pixel depth.

Order.  Exact (the reference): all contributions of a pixel (alpha >= 1/255) sorted by
``(t*, position in the tile's list)``, then blended front to back with the usual early stop.
Windowed (:func:`window_order`, the twin of the tile renderer): the tile's list is read in
order and each pixel holds back up to ``W`` contributions; each new one joins them and, when
that makes ``W + 1``, the nearest is blended; the rest are blended in order at the end of the
list, and at every TILE_LIST_CHUNK-th entry (the tile renderer's pass boundary).  Exact when no
contribution arrives more than ``W`` places after one it should precede.
"""

from __future__ import annotations

import numpy as np

from ..constants import TILE_LIST_CHUNK
from .chunk import (TILE_PIXELS, ChunkSplats, blend_chunk, chunk_alpha, surfel_chunk_alpha,
                    tile_centres, tile_outputs)
from ..splatmath.peak import Rays, peak_depth
from .stages import ProjectedSplats

#: List entries evaluated per step while collecting a tile's contributions.
COLLECT_CHUNK = 256


def _contributions(proj: ProjectedSplats, values: np.ndarray, start: int, end: int,
                   px: np.ndarray, py: np.ndarray, rays: Rays | None, options
                   ) -> tuple[np.ndarray, ...]:
    """Every (pixel, splat) pair of one tile with alpha >= the skip threshold, as flat arrays
    ``(pixel (M,), list position (M,), t (M,), alpha (M,), colour (M, 3))`` in list order
    (``rays``: the camera's, for 3DGS; surfels sort by their hit's z and need none)."""
    dt = proj.dtype.type
    if not proj.is_surfel:
        ax = ((px - dt(rays.cx)) / dt(rays.fx))[None, :]         # (1, 16) by column
        ay = ((py - dt(rays.cy)) / dt(rays.fy))[None, :]         # (1, 16) by row
    out = []
    for s in range(start, end, COLLECT_CHUNK):
        pos = np.arange(s, min(s + COLLECT_CHUNK, end))[None]
        g = ChunkSplats(proj, values, pos, pos < end)
        if proj.is_surfel:
            alpha, t = surfel_chunk_alpha(g, px[None], py[None], options.resolved_alpha_max,
                                          options.compat, options.alpha_min)
        else:
            alpha = chunk_alpha(g, px[None], py[None], options.resolved_alpha_max, options.alpha_min)
            pk = proj.peak[values[pos]][0]                          # (K, 10)
            t = peak_depth(pk[:, None, None, :], ax[:, None, :], ay[0][None, :, None], rays.parallel)
            t = t.reshape(1, -1, TILE_PIXELS)
        k, pix = np.nonzero(alpha[0] > 0)
        out.append((pix, pos[0, k], t[0, k, pix], alpha[0, k, pix], g.color[0, k]))
    return tuple(np.concatenate(parts) for parts in zip(*out))


def exact_order(pix: np.ndarray, pos: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Indices of the contributions sorted by pixel, then ``t*``, then list position."""
    return np.lexsort((pos, t, pix))


def window_order(pix: np.ndarray, pos: np.ndarray, t: np.ndarray, window: int,
                 chunk: int = TILE_LIST_CHUNK) -> np.ndarray:
    """Indices of the contributions sorted by pixel, then in the order the tile renderer's
    window of ``window`` splats blends them (module doc); (M,) arrays in list order, ``pos``
    counted from the tile's first entry."""
    order = np.lexsort((pos, pix))                     # by pixel, in arrival order
    out = np.empty(len(order), np.int64)
    done = 0
    for p in np.unique(pix):
        rows = order[pix[order] == p]
        for seg in np.split(rows, np.flatnonzero(np.diff(pos[rows] // chunk)) + 1):
            emitted = _window(seg, t[seg], pos[seg], window)
            out[done:done + len(emitted)] = emitted
            done += len(emitted)
    return out


def _window(ids: np.ndarray, t: np.ndarray, pos: np.ndarray, window: int) -> list:
    """One pixel's entries (in arrival order) in the order a window of ``window`` emits them."""
    held: list[tuple] = []
    emitted = []
    for i in range(len(ids)):
        held.append((t[i], pos[i], ids[i]))
        if len(held) > window:
            j = min(range(len(held)), key=lambda n: held[n][:2])
            emitted.append(held.pop(j)[2])
    emitted.extend(e[2] for e in sorted(held, key=lambda e: e[:2]))
    return emitted


def check_projection(proj: ProjectedSplats, layers) -> None:
    """ValueError unless ``proj`` was projected for the per-pixel order (3DGS: its ``peak``
    coefficients and ``rays``) and no further layers are asked for."""
    if not proj.is_surfel and (proj.peak is None or proj.rays is None):
        raise ValueError("the projection has no peak coefficients (project with the per-pixel order)")
    if layers is not None:
        raise ValueError("the per-pixel order computes no further layers")


def raster_batch(proj: ProjectedSplats, values: np.ndarray, ranges: np.ndarray,
                 tiles: np.ndarray, options):
    """Blend the tiles ``tiles`` (b,) in the per-pixel order (exact, or the tile renderer's
    window when ``options.window`` is set): the per-pixel half of
    :func:`splatgl.reference.rasterize.rasterize`, with the same outputs as its global batch."""
    out_t, out_c, out_d, out_n, out_b = tile_outputs(tiles.shape[0], proj.dtype)
    cols, rows = tile_centres(tiles, proj)
    for row, tile in enumerate(tiles):
        start, end = (int(v) for v in ranges[tile])
        if end <= start:
            continue
        pix, pos, t, alpha, color = _contributions(proj, values, start, end, cols[row], rows[row],
                                                   proj.rays, options)
        if not len(pix):
            continue
        idx = (exact_order(pix, pos, t) if options.window is None
               else window_order(pix, pos - start, t, options.window))
        pix, pos, t, alpha, color = pix[idx], pos[idx], t[idx], alpha[idx], color[idx]
        counts = np.bincount(pix, minlength=TILE_PIXELS)
        rank = np.arange(len(pix)) - (np.cumsum(counts) - counts)[pix]
        length = int(counts.max())
        a = np.zeros((1, length, TILE_PIXELS), proj.dtype)
        a[0, rank, pix] = alpha
        w, kept, t_seq = blend_chunk(np.ones((1, TILE_PIXELS), proj.dtype), a, options.stop_inclusive)
        wk = w[0, rank, pix]                                   # per contribution
        np.add.at(out_c[row], pix, wk[:, None] * color)
        np.add.at(out_d[row], pix, wk * t)
        out_t[row] = np.take_along_axis(t_seq, kept[:, None, :], axis=1)[0, 0]
        blended = wk > 0                                     # a prefix of each pixel's list
        out_b[row] = np.bincount(pix[blended], minlength=TILE_PIXELS)
        last = blended & (rank == out_b[row][pix] - 1)
        last_pos = np.zeros(TILE_PIXELS, np.int64)
        last_pos[pix[last]] = pos[last] - start + 1
        out_n[row] = last_pos
    return out_t, out_c, out_d, out_n, out_b

