"""Fused float32 cull of the lens cameras (fisheye, equirectangular): sort keys in one pass.

The same decisions, in the same float32 arithmetic, as :func:`lens_cull` followed
by :func:`lens_order` (the float64 twins at the end of this module) (distance beyond the near plane, a fisheye's angle limit,
opacity >= 1/255, equirectangular seam copies), run over blocks of
:data:`~splatgl.order.cull.CULL_BLOCK` rows of the chunked cull data (:mod:`splatgl.order.chunks`,
whose rows are already the drawable splats) into reused buffers, and written straight into
uint64 sort keys ``(float_bits(distance) << 32) | index`` (seam copies with
:data:`~splatgl.cameras.equirect.WRAP_FLAG` in the index).

Two tests are first made cheaply, with exact fallbacks where the cheap test cannot decide:

- fisheye angle ``atan2(rho, z) <= theta_max`` is ``z >= cos(theta_max) |p|``; splats within
  :data:`ANGLE_BAND` (relative) of that cone take the float32 ``arctan2`` test as before;
- equirectangular seam copies: a float32 bound of the reach, widened by :data:`ANGLE_BAND`,
  picks the candidates; :func:`splatgl.cameras.equirect.wrap_copies` (float64) decides on them.
"""

from __future__ import annotations

import numpy as np

from ..cameras.camera import Camera
from ..cameras.equirect import SEAM_MARGIN_PX, WRAP_FLAG, eye_space, wrap_copies
from ..constants import ALPHA_MIN
from ..splatmath.project import splat_reach
from .cull import CULL_BLOCK, CullData, view_axis
from .chunks import ChunkedCull
from .sort import depth_keys

#: Relative width of the band around a cheap test's boundary where the exact test decides
#: (float32 rounding of the distance and of ``arctan2`` is below 1e-6 relative).
ANGLE_BAND = 1e-4


def lens_visible_keys(chunks: ChunkedCull, camera: Camera, near: float, scale: float = 1.0
                      ) -> np.ndarray:
    """(K,) uint64 unsorted sort keys of a lens camera's kept splats and seam copies (without
    copies, a view of ``chunks``' key buffer, which the next cull overwrites).

    ``camera`` anchored to ``chunks.data.xyz``'s origin; ``scale``: the model's uniform scale
    (multiplies the world reach of the seam test).  Same keys as :func:`lens_cull`
    + :func:`lens_order` give through :func:`splatgl.order.sort.depth_keys`.
    """
    chunks.views += 1
    kern = chunks._kernel() if not getattr(camera.model, "ods_eye", 0.0) else None
    keys, chunks.last_path = lens_keys(chunks.data, chunks.index, chunks.key_buffer(), camera,
                                       near, scale, kern)
    return keys


def lens_keys(data: CullData, index: np.ndarray, keys: np.ndarray, camera: Camera, near: float,
              scale: float = 1.0, kern=None) -> tuple[np.ndarray, str]:
    """:func:`lens_visible_keys` of the rows of ``data`` (drawable splats only), whose keys
    carry ``index`` (their (M,) uint32 indices), written into ``keys`` (at least M long):
    ``(keys, "compiled" or "numpy")``.  ``kern``: the compiled ``lens_pass``'s kernels, or None."""
    n = data.count
    rot = camera.rotation.astype(np.float32)
    t = camera.translation.astype(np.float32)
    near32 = np.float32(near)  # lens_visible compares float32 distances with the Python float
    limit = camera.model.angle_limit(camera)
    fisheye = limit is not None
    equirect = camera.model.seam_period(camera) is not None
    ods_eye = getattr(camera.model, "ods_eye", 0.0)
    limit32 = cos_limit = np.float32(0.0)
    if fisheye:
        limit32, cos_limit = np.float32(limit), np.float32(np.cos(limit))
    if kern is not None and not ods_eye:
        done = _compiled_keys(kern, data, index, keys, camera, near32, limit32, cos_limit, scale)
        if done is not None:
            return done, "compiled"
    block = min(CULL_BLOCK, max(n, 1))
    x, y, z, d, tmp = (np.empty(block, np.float32) for _ in range(5))
    keep, band = np.empty(block, bool), np.empty(block, bool)
    out, copies = 0, []
    for start in range(0, n, block):
        stop = min(n, start + block)
        m = stop - start
        xb, yb, zb, db, tb, kb, bb = x[:m], y[:m], z[:m], d[:m], tmp[:m], keep[:m], band[:m]
        for axis, row in enumerate((xb, yb, zb)):
            view_axis(data.xyz, start, stop, rot[axis], t[axis], row, tb)
        if ods_eye:
            p = eye_space(np.stack([xb, yb, zb], 1), camera)
            xb[:], yb[:], zb[:] = p[:, 0], p[:, 1], p[:, 2]
        np.multiply(xb, xb, out=db)  # einsum("ni,ni->n")'s sum, in its order
        np.multiply(yb, yb, out=tb)
        db += tb
        np.multiply(zb, zb, out=tb)
        db += tb
        np.sqrt(db, out=db)
        np.greater(db, near32, out=kb)
        if fisheye:
            np.multiply(db, cos_limit, out=tb)  # cheap cone test with a band of doubt
            np.subtract(zb, tb, out=tb)
            np.less(np.abs(tb), db * np.float32(ANGLE_BAND), out=bb)
            kb &= tb >= 0
            kb |= bb & (db > near32)
            doubt = np.flatnonzero(bb & kb)
            if doubt.size:
                theta = np.arctan2(np.hypot(xb[doubt], yb[doubt]), zb[doubt])
                kb[doubt[theta > limit32]] = False
        if equirect:  # seam candidates from a float32 bound of the reach, on the whole block
            np.multiply(data.radius[start:stop], np.float32(scale), out=tb)
            tb += db * np.float32(SEAM_MARGIN_PX / camera.fx)
            tb *= np.float32(1.0 + ANGLE_BAND)
            cand = np.flatnonzero(kb & (np.abs(xb) < tb) & (zb < tb))
            if cand.size:
                cand = cand[_seam_copies(data, start + cand, xb[cand], yb[cand], zb[cand],
                                         camera, scale)]
                copies.append(depth_keys(db[cand], index[start + cand] | WRAP_FLAG))
        if kb.all():  # no compaction
            depth_keys(db, index[start:stop], keys[out:out + m])
            out += m
        else:
            idx = np.flatnonzero(kb)
            depth_keys(db[idx], index[start + idx], keys[out:out + idx.size])
            out += idx.size
    return (np.concatenate([keys[:out], *copies]) if copies else keys[:out]), "numpy"


def _seam_copies(data: CullData, rows: np.ndarray, x, y, z, camera: Camera,
                 scale: float) -> np.ndarray:
    """(R,) bool: which of the kept splats ``rows`` (with camera-space ``x, y, z`` (R,)
    float32) :func:`splatgl.cameras.equirect.wrap_copies` duplicates (its float64 test, its reach)."""
    radius = splat_reach(data.max_scale[rows] * scale, data.opacities[rows])
    return wrap_copies(np.stack([x, y, z], 1), radius, camera)


#: Room per half of the rows for the compiled pass's fisheye rows near the cone and equirect
#: seam candidates (more and the view takes the NumPy path).
LIST_ROWS = 1 << 16


def _compiled_keys(kern, data: CullData, index: np.ndarray, keys: np.ndarray, camera: Camera,
                   near32: np.float32, limit32: np.float32, cos_limit: np.float32, scale: float
                   ) -> np.ndarray | None:
    """:func:`lens_visible_keys` through the compiled ``lens_pass`` (over two threads from
    :data:`splatgl.order.chunks.SPLIT_ROWS` rows, as the pinhole pass): NumPy's ``arctan2`` on
    the fisheye rows it leaves in doubt, NumPy's float64 seam test on its candidates; None if
    either list overflows."""
    from . import chunks as cull_chunks, kernels as cull_kernel

    n = data.count
    mode = 1 if camera.model.angle_limit(camera) is not None else (
        2 if camera.model.seam_period(camera) is not None else 0)
    args = (data.xyz[0], data.xyz[1], data.xyz[2], data.radius, index,
            camera.rotation.astype(np.float32), camera.translation.astype(np.float32), near32,
            mode, cos_limit, np.float32(ANGLE_BAND), np.float32(scale),
            np.float32(SEAM_MARGIN_PX / camera.fx), keys.view(np.uint32),
            keys.view(np.float32))
    lists = lambda: (np.empty(LIST_ROWS, np.int64), np.empty((LIST_ROWS, 4), np.float32),
                     np.empty(LIST_ROWS, np.int64), np.empty((LIST_ROWS, 4), np.float32))
    pool = cull_kernel.helper() if n >= cull_chunks.SPLIT_ROWS else None
    starts = [0] if pool is None else [0, n // 2]
    found = [lists() for _ in starts]
    if pool is None:
        results = [kern.lens_pass(0, n, 0, *args, *found[0])]
    else:
        second = pool.submit(kern.lens_pass, n // 2, n, n // 2, *args, *found[1])
        try:
            first = kern.lens_pass(0, n // 2, 0, *args, *found[0])
        finally:
            last = second.result()  # its writes must end before the buffer is reused
        results = [first, last]
    if any(nd > LIST_ROWS or ns > LIST_ROWS for _, nd, ns in results):
        return None
    out = 0
    for at, (count, _, _) in zip(starts, results):
        keys[out:out + count] = keys[at:at + count]  # overlapping: NumPy buffers it
        out += count
    copies = []
    for (_, nd, ns), (doubt, doubt_p, seam, seam_p) in zip(results, found):
        if nd:  # near the fisheye's cone: the float32 arctan2 test, as the NumPy path
            rows, p = doubt[:nd], doubt_p[:nd]
            ok = ~(np.arctan2(np.hypot(p[:, 0], p[:, 1]), p[:, 2]) > limit32)
            depth_keys(p[ok, 3], index[rows[ok]], keys[out:out + int(ok.sum())])
            out += int(ok.sum())
        if ns:  # near the equirect seam: the float64 copy test on the candidates
            rows, p = seam[:ns], seam_p[:ns]
            pick = _seam_copies(data, rows, p[:, 0], p[:, 1], p[:, 2], camera, scale)
            copies.append(depth_keys(p[pick, 3], index[rows[pick]] | WRAP_FLAG))
    return np.concatenate([keys[:out], *copies]) if copies else keys[:out]


# ---------------------------------------------------------------------------- float64 twins
def lens_cull(p_cam: np.ndarray, opacities: np.ndarray, camera: Camera, near: float) -> np.ndarray:
    """(N,) bool keep mask of a lens camera: the model's ``visible`` and opacity >= 1/255.

    (No screen test: a fisheye or panorama sees most of a scene; the rasterizer drops the rest.)
    """
    return camera.model.visible(eye_space(p_cam, camera), camera, near) & (opacities >= ALPHA_MIN)


def lens_order(p_cam: np.ndarray, keep: np.ndarray, radius: np.ndarray, camera: Camera
               ) -> tuple[np.ndarray, np.ndarray]:
    """Sort inputs of a lens camera's kept splats: ``(depths (M,), indices (M,) uint32)``.

    ``keep``: (K,) indices of the kept splats; ``radius``: (K,) their world reach.  Depth is
    the distance; seam splats of an equirectangular camera appear twice, the copy with
    :data:`~splatgl.cameras.equirect.WRAP_FLAG` set in its index and the same depth.
    """
    pk = eye_space(p_cam[keep], camera)
    depth = camera.model.depth(pk).astype(np.float32)
    idx = keep.astype(np.uint32)
    dup = wrap_copies(pk, radius, camera)
    if dup.any():
        depth = np.concatenate([depth, depth[dup]])
        idx = np.concatenate([idx, idx[dup] | WRAP_FLAG])
    return depth, idx
