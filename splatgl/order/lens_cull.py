"""Fused float32 cull of the lens cameras (fisheye, equirectangular): sort keys in one pass.

The decisions (distance beyond the near plane, a fisheye's angle limit, opacity >= 1/255,
equirectangular seam copies) are float32 operations without transcendentals, so the device
order (``shaders/order_cull.comp``, ``--sort gpu``) makes them bit for bit too: one decision,
two implementations (:func:`cone_keeps`, :func:`seam_copies` are its NumPy twins).  They run
over blocks of :data:`~splatgl.order.cull.CULL_BLOCK` rows of the chunked cull data
(:mod:`splatgl.order.chunks`, whose rows are already the drawable splats) into reused buffers,
and are written straight into uint64 sort keys ``(float_bits(distance) << 32) | index`` (seam
copies with :data:`~splatgl.cameras.equirect.WRAP_FLAG` in the index):

- distance ``d = sqrt((x x + y y) + z z)`` and ``d > near`` (float32);
- fisheye angle ``atan2(rho, z) <= theta_max`` as ``z - d cos(theta_max) >= 0`` (float32, the
  cosine rounded once on the host): it differs from a float32 ``arctan2`` test only on splats
  within rounding of the cone, which lies :data:`~splatgl.constants.FISHEYE_THETA_MARGIN`
  beyond the image's farthest corner;
- equirectangular seam copies: ``|x| < reach and z < reach`` with
  ``reach = radius scale + d (SEAM_MARGIN_PX / fx)`` (float32; radius the cull data's
  ``k(o) max_scale``): :func:`splatgl.cameras.equirect.wrap_copies`' test, whose float64
  reach it equals up to rounding (a copy within rounding of it lies ``SEAM_MARGIN_PX`` beyond
  the splat's reach: it draws nothing either way).  A float32 bound widened by
  :data:`ANGLE_BAND` picks the candidates cheaply; the exact float32 test decides on them.

Omni-directional stereo moves each point to its eye with ``arctan2``/``arcsin``/``cos``/``sin``
(:func:`~splatgl.cameras.equirect.eye_space`), which no device reproduces bit for bit: those
views keep the CPU cull (the device order does not cover them).
:func:`lens_cull` + :func:`lens_order` (the float64 twins at the end of this module) are the
model's own tests, which these equal up to rounding.
"""

from __future__ import annotations

import numpy as np

from ..cameras.camera import Camera
from ..cameras.equirect import SEAM_MARGIN_PX, WRAP_FLAG, eye_space, wrap_copies
from ..constants import ALPHA_MIN
from .cull import CULL_BLOCK, CullData, view_axis
from .chunks import ChunkedCull
from .sort import depth_keys

#: Relative widening of the cheap seam bound that picks the candidates the exact float32 seam
#: test decides on (float32 rounding is below 1e-6 relative).
ANGLE_BAND = 1e-4


def cone_keeps(z: np.ndarray, d: np.ndarray, cos_limit: np.float32) -> np.ndarray:
    """(N,) bool: a fisheye keeps the points at camera-space ``z`` and distance ``d`` (float32):
    ``z - d cos_limit >= 0``, in float32 (``shaders/order_cull.comp``'s ``CULL_FISHEYE``)."""
    return (z - d * np.float32(cos_limit)) >= np.float32(0)


def seam_copies(x: np.ndarray, z: np.ndarray, d: np.ndarray, radius: np.ndarray,
                scale: np.float32, seam_px: np.float32) -> np.ndarray:
    """(N,) bool: the kept splats at camera-space ``x, z``, distance ``d`` and world radius
    ``radius`` (float32, the cull data's) an equirectangular view draws twice:
    ``reach = radius scale + d seam_px``, ``|x| < reach and z < reach`` in float32
    (``shaders/order_cull.comp``'s ``CULL_SEAM``; ``seam_px = SEAM_MARGIN_PX / fx``)."""
    reach = radius * np.float32(scale)
    reach += d * np.float32(seam_px)
    return (np.abs(x) < reach) & (z < reach)


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
    cos_limit = np.float32(np.cos(limit)) if fisheye else np.float32(0.0)
    scale32, seam_px = np.float32(scale), np.float32(SEAM_MARGIN_PX / camera.fx)
    if kern is not None and not ods_eye:
        done = _compiled_keys(kern, data, index, keys, camera, near32, cos_limit, scale)
        if done is not None:
            return done, "compiled"
    block = min(CULL_BLOCK, max(n, 1))
    x, y, z, d, tmp = (np.empty(block, np.float32) for _ in range(5))
    keep = np.empty(block, bool)
    out, copies = 0, []
    for start in range(0, n, block):
        stop = min(n, start + block)
        m = stop - start
        xb, yb, zb, db, tb, kb = x[:m], y[:m], z[:m], d[:m], tmp[:m], keep[:m]
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
            kb &= cone_keeps(zb, db, cos_limit)
        if equirect:  # seam candidates from a float32 bound of the reach, on the whole block
            np.multiply(data.radius[start:stop], scale32, out=tb)
            tb += db * seam_px
            tb *= np.float32(1.0 + ANGLE_BAND)
            cand = np.flatnonzero(kb & (np.abs(xb) < tb) & (zb < tb))
            if cand.size:
                cand = cand[seam_copies(xb[cand], zb[cand], db[cand],
                                        data.radius[start + cand], scale32, seam_px)]
                copies.append(depth_keys(db[cand], index[start + cand] | WRAP_FLAG))
        if kb.all():  # no compaction
            depth_keys(db, index[start:stop], keys[out:out + m])
            out += m
        else:
            idx = np.flatnonzero(kb)
            depth_keys(db[idx], index[start + idx], keys[out:out + idx.size])
            out += idx.size
    return (np.concatenate([keys[:out], *copies]) if copies else keys[:out]), "numpy"


#: Room per half of the rows for the compiled pass's equirect seam candidates (more and the
#: view takes the NumPy path).
LIST_ROWS = 1 << 16


def _compiled_keys(kern, data: CullData, index: np.ndarray, keys: np.ndarray, camera: Camera,
                   near32: np.float32, cos_limit: np.float32, scale: float) -> np.ndarray | None:
    """:func:`lens_visible_keys` through the compiled ``lens_pass`` (over two threads from
    :data:`splatgl.order.chunks.SPLIT_ROWS` rows, as the pinhole pass): its own float32 cone
    test, NumPy's float32 seam test (:func:`seam_copies`) on its candidates; None if their
    list overflows."""
    from . import chunks as cull_chunks, kernels as cull_kernel

    n = data.count
    mode = 1 if camera.model.angle_limit(camera) is not None else (
        2 if camera.model.seam_period(camera) is not None else 0)
    scale32, seam_px = np.float32(scale), np.float32(SEAM_MARGIN_PX / camera.fx)
    args = (data.xyz[0], data.xyz[1], data.xyz[2], data.radius, index,
            camera.rotation.astype(np.float32), camera.translation.astype(np.float32), near32,
            mode, cos_limit, np.float32(ANGLE_BAND), scale32, seam_px, keys.view(np.uint32),
            keys.view(np.float32))
    lists = lambda: (np.empty(LIST_ROWS, np.int64), np.empty((LIST_ROWS, 4), np.float32))
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
    if any(ns > LIST_ROWS for _, _, ns in results):
        return None
    out = 0
    for at, (count, _, _) in zip(starts, results):
        keys[out:out + count] = keys[at:at + count]  # overlapping: NumPy buffers it
        out += count
    copies = []
    for (_, _, ns), (seam, seam_p) in zip(results, found):
        if ns:  # near the equirect seam: the float32 copy test on the candidates
            rows, p = seam[:ns], seam_p[:ns]
            pick = seam_copies(p[:, 0], p[:, 2], p[:, 3], data.radius[rows], scale32, seam_px)
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
