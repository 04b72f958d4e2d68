"""CPU cull stage: which splats can touch the image (before the sort and the draw).

Culls on view-space z before any perspective divide (points behind the camera would mirror into
view after it), then tests a conservative bound of each splat's extent against the screen: the
sphere of radius ``k * max(scale)`` (k = the opacity-aware sigma count, at most
sqrt(2 ln 255) ~ 3.33) widened by the low-pass dilation's reach, against the four side planes
of the view frustum (an axis-aligned box for orthographic cameras).  Splats with opacity below
1/255 go, and so do splats whose alpha cannot reach 1/255 at any pixel centre
(:func:`peak_alpha_bound`): tiny splats between pixel centres, and with antialiasing every
splat whose compensation factor pushes it under the cut.
"""

from __future__ import annotations

import numpy as np

from ..cameras.camera import Camera
from ..constants import AA_MIN_FACTOR, ALPHA_MIN, JACOBIAN_CLAMP, LOW_PASS
from ..cameras.model import CullKind
from ..cameras.view import Frustum, frustum_of, near_threshold

#: Extra screen margin (pixels) so the 0.3 px^2 dilation and pixel-centre rounding never cull
#: a splat whose quad would touch the image.
MARGIN_PX = 3.33 * float(np.sqrt(LOW_PASS)) + 1.0


def peak_alpha_bound(p_cam: np.ndarray, max_scale: np.ndarray, opacities: np.ndarray,
                     camera: Camera, antialias: bool = False) -> np.ndarray:
    """(N,) upper bound of the largest alpha a splat reaches at any pixel centre of the image.

    With ``d`` the distance from the projected centre to the nearest pixel centre inside the
    image, ``d^T Q d >= |d|^2 / lambda_max`` for the conic Q, and
    ``lambda_max <= ||J||_F^2 max_scale^2 + LOW_PASS`` (``||W||_2 = 1``; J the clamped EWA
    Jacobian).  So ``alpha <= o * aa * exp(-|d|^2 / (2 lambda_bound))``, where with
    antialiasing ``aa = sqrt(det / det_dilated) <= 1 - LOW_PASS / lambda_bound`` (each
    eigenvalue's factor (l - 0.3) / l grows with l), floored like the reference's factor,
    and bounded once more by ``exp(-a - a^2 / 2) >= 1 - a`` (``a = LOW_PASS / lambda_bound``:
    :func:`peak_keeps`' float32 form, free of transcendentals, has no log of it).
    Only valid for splats in front of the camera (z > 0).
    """
    x, y, z = (p_cam[:, i].astype(np.float64) for i in range(3))
    if camera.is_orthographic:
        jf2 = np.full_like(z, camera.fx ** 2 + camera.fy ** 2)
        u, v = camera.fx * x + camera.cx, camera.fy * y + camera.cy
    else:
        zs = np.where(z > 0, z, 1.0)
        tx, ty = camera.tan_half_fov
        xc = np.clip(x / zs, -JACOBIAN_CLAMP * tx, JACOBIAN_CLAMP * tx)
        yc = np.clip(y / zs, -JACOBIAN_CLAMP * ty, JACOBIAN_CLAMP * ty)
        jf2 = (camera.fx ** 2 * (1 + xc * xc) + camera.fy ** 2 * (1 + yc * yc)) / (zs * zs)
        u, v = camera.fx * x / zs + camera.cx, camera.fy * y / zs + camera.cy
    lam = jf2 * max_scale.astype(np.float64) ** 2 + LOW_PASS
    # nearest pixel centre inside the image: (clip(round(u - 0.5), 0, W - 1) + 0.5, ...)
    with np.errstate(invalid="ignore"):
        nu = np.clip(np.round(u - 0.5), 0, camera.width - 1) + 0.5
        nv = np.clip(np.round(v - 0.5), 0, camera.height - 1) + 0.5
        d2 = (u - nu) ** 2 + (v - nv) ** 2
        bound = opacities.astype(np.float64) * np.exp(-0.5 * d2 / lam)
    if antialias:   # exp(-a - a^2 / 2) >= 1 - a: peak_keeps' bound of the factor
        a = LOW_PASS / lam
        bound *= np.maximum(np.exp(-(a + 0.5 * a * a)), np.sqrt(AA_MIN_FACTOR))
    return np.where(np.isfinite(bound), bound, 1.0)  # never cull on a non-finite bound


def cull(p_cam: np.ndarray, max_scale: np.ndarray, opacities: np.ndarray, camera: Camera,
         near: float, antialias: bool = False) -> np.ndarray:
    """Boolean mask (N,) of splats to keep.

    Args:
        p_cam: (N, 3) camera-space centres (float32 or float64).
        max_scale: (N,) largest scale of each splat (world units).
        opacities: (N,) opacities; below 1/255 a splat can never be drawn.
        camera: the view.  near: view z at or below which splats are culled.
        antialias: whether the opacity compensation applies (tightens the peak bound).

    A model with its own cull frustum (:meth:`~splatgl.cameras.model.CameraModel.cull_frustum`,
    lens distortion) is culled against that frustum's planes without the peak bound
    (:func:`splatgl.cameras.view.frustum_of`, which gives the planes).
    """
    frustum = frustum_of(camera)
    peak, camera = frustum.peak, frustum.camera
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        k = np.sqrt(np.maximum(2.0 * np.log(np.maximum(opacities, 1e-30) / ALPHA_MIN), 0.0))
    radius = (k * max_scale).astype(np.float64)
    x, y, z = (p_cam[:, i].astype(np.float64) for i in range(3))
    keep = (z > near) & (opacities >= ALPHA_MIN)
    if camera.is_orthographic:   # the box's edges
        for coord, (f, lo, hi) in zip((x, y), frustum.edges):
            keep &= (coord >= lo - (radius + MARGIN_PX / f)) & (coord <= hi + (radius + MARGIN_PX / f))
        return _peak_cull(keep, p_cam, max_scale, opacities, camera, antialias) if peak else keep
    # Side planes through the camera centre: x / z = s for slopes s at the image edges.
    # The signed distance of a point from the plane x - s z = 0 is (x - s z) / sqrt(1 + s^2).
    for coord, (f, _lo, _hi), (lo, n_lo, hi, n_hi) in zip((x, y), frustum.edges, frustum.sides):
        reach = radius + MARGIN_PX * np.maximum(z, 0.0) / f
        keep &= (coord - hi * z) / n_hi <= reach
        keep &= (lo * z - coord) / n_lo <= reach
    return _peak_cull(keep, p_cam, max_scale, opacities, camera, antialias) if peak else keep


def _peak_cull(keep, p_cam, max_scale, opacities, camera, antialias) -> np.ndarray:
    """``keep`` minus the splats that cannot reach 1/255 at any pixel (bound on survivors only)."""
    idx = np.flatnonzero(keep)
    bound = peak_alpha_bound(p_cam[idx], max_scale[idx], opacities[idx], camera, antialias)
    keep[idx[bound < ALPHA_MIN]] = False
    return keep


#: Rows per block of :func:`cull_visible`: small enough that a block's float32 temporaries
#: stay in the CPU's L2 cache (64 Ki rows x 4 B = 256 KiB per temporary).
CULL_BLOCK = 1 << 15


class CullData:
    """The view-independent part of the cull, computed once per scene.

    Attributes:
        xyz: (3, N) float32 centres relative to the scene's anchor (``Scene.relative_means``
            transposed: one contiguous row per axis, which NumPy streams several times faster
            than the strided columns of an (N, 3) array).
        radius: (N,) float32 world radius ``k(o) * max_scale`` of the sphere that holds every
            point where the splat's alpha can reach 1/255 (k as in :func:`cull`).
        max_scale: (N,) float32.  opacities: (N,) float32.
        alive: (N,) bool, opacity >= 1/255 (a splat below can never be drawn).
        faint: (N,) bool, ``k^2 < 0.5 / LOW_PASS``: the peak bound can cull such a splat even
            with its centre inside the image (for the others it only can outside).
        cut_log: (N,) float32 ``log(255 o) = k^2 / 2`` (float64, rounded once): the peak
            bound's level (:func:`peak_keeps`; the device order's cull rows carry it).
    """

    def __init__(self, points: np.ndarray, max_scale: np.ndarray, opacities: np.ndarray):
        self.xyz = np.ascontiguousarray(np.asarray(points, np.float32).T)
        self.max_scale = np.ascontiguousarray(max_scale, np.float32)
        self.opacities = np.ascontiguousarray(opacities, np.float32)
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            k2 = np.maximum(2.0 * np.log(np.maximum(self.opacities, 1e-30) / ALPHA_MIN), 0.0)
        self.radius = (np.sqrt(k2) * self.max_scale).astype(np.float32)
        self.alive = self.opacities >= ALPHA_MIN
        self.faint = k2 < 0.5 / LOW_PASS
        self.cut_log = (0.5 * k2).astype(np.float32)   # log(255 o) (0 where o < 1/255)

    @property
    def count(self) -> int:
        return int(self.xyz.shape[1])

    def subset(self, rows: np.ndarray) -> "CullData":
        """The cull data of ``rows`` (index array, or a slice: then views, no copy) only, in
        that order (no recomputation)."""
        out = object.__new__(CullData)
        # each row of xyz must be contiguous (the cull streams rows); a column slice keeps that
        # (np.take: fancy indexing on the second axis gives a non-contiguous array, twice as slow)
        out.xyz = self.xyz[:, rows] if isinstance(rows, slice) else np.take(self.xyz, rows, axis=1)
        for name in ("max_scale", "opacities", "radius", "alive", "faint", "cut_log"):
            setattr(out, name, getattr(self, name)[rows])
        return out

    @classmethod
    def from_scene(cls, scene, block: int = 1 << 16) -> "CullData":
        """The cull data of a :class:`splatgl.scene.splats.Scene`, activated block by block (no
        full-size activated copy of the scene is made or cached)."""
        n = scene.count
        xyz = np.empty((3, n), np.float32)
        max_scale = np.empty(n, np.float32)
        opac = np.empty(n, np.float32)
        for start in range(0, n, block):
            rows = scene.activated_rows(start, min(n, start + block))
            xyz[:, start:start + block] = rows.relative_means.T
            max_scale[start:start + block] = rows.scales.max(axis=1)
            opac[start:start + block] = rows.opacities
        return cls(xyz.T, max_scale, opac)


def cull_visible(data: CullData, camera: Camera, near: float, antialias: bool = False,
                 scale: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """The splats :func:`cull` keeps, with their view depths: ``(indices (M,) uint32 ascending,
    z (M,) float32)``.

    Same tests as :func:`cull` (near plane, opacity, extent sphere against the four side planes,
    peak alpha bound), fused with the camera transform and run in float32 over blocks of
    :data:`CULL_BLOCK` rows into reused buffers, so a block's temporaries stay in cache.
    ``camera`` must already be anchored to ``data.xyz``'s origin; ``scale`` multiplies the
    world radii (a scene transform's uniform scale).

    The plane test ``(x - s z) / sqrt(1 + s^2) <= r + m z / f`` is rearranged to
    ``x <= (s + sqrt(1 + s^2) m / f) z + sqrt(1 + s^2) r`` (likewise for the other three
    planes).  The peak alpha bound (:func:`peak_keeps`: :func:`peak_alpha_bound`'s decision in
    float32, the device order's bit for bit) runs only where it can cull: on survivors whose centre projects outside the image, or that are faint (a centre
    inside the image lies within 0.5 px per axis of a pixel centre, d^2 <= 0.5, and
    ``lambda >= LOW_PASS``, so ``o exp(-d^2 / (2 lambda)) >= 1/255`` whenever
    ``k^2 = 2 ln(255 o) >= 0.5 / LOW_PASS``).  With antialiasing every survivor takes it.
    Orthographic cameras run the same float32 tests with z's factor 1 (:func:`plane_constants`:
    the box's edges; :func:`cull`'s box up to rounding, within the margin where a splat draws
    nothing), so the device order (shaders/order_cull.comp) makes the same decisions.  A model
    with its own cull frustum
    (:meth:`~splatgl.cameras.model.CameraModel.cull_frustum`, lens distortion) is culled against
    that frustum's planes without the peak bound.
    """
    n = data.count
    frustum = frustum_of(camera)
    camera, peak = frustum.camera, frustum.peak
    box = frustum.kind is CullKind.BOX
    r = camera.rotation.astype(np.float32)
    t = camera.translation.astype(np.float32)
    planes = plane_constants(frustum, scale)
    near32 = near_threshold(near, np.float32)
    block = min(CULL_BLOCK, max(n, 1))
    z, v, w, u = (np.empty(block, np.float32) for _ in range(4))
    ones = np.ones(block, np.float32)   # a box's planes: z's factor is 1 (plane_constants)
    keep, inside, tmp = (np.empty(block, bool) for _ in range(3))
    out_idx, out_z = [], []
    for start in range(0, n, block):
        stop = min(n, start + block)
        m = stop - start
        zb, vb, wb, ub = z[:m], v[:m], w[:m], u[:m]
        kb, ib, tb = keep[:m], inside[:m], tmp[:m]
        view_axis(data.xyz, start, stop, r[2], t[2], zb, wb)
        np.greater(zb, near32, out=kb)
        kb &= data.alive[start:stop]
        rad = data.radius[start:stop]
        zp = ones[:m] if box else zb
        ib.fill(True)
        for axis, (a_hi, b_hi, a_lo, b_lo, lo, hi) in enumerate(planes):
            view_axis(data.xyz, start, stop, r[axis], t[axis], vb, wb)
            for a, b, upper in ((a_hi, b_hi, True), (a_lo, b_lo, False)):
                np.multiply(rad, b, out=wb)
                np.multiply(zp, a, out=ub)
                wb += ub
                (np.less_equal if upper else np.greater_equal)(vb, wb, out=tb)
                kb &= tb
            np.multiply(zp, hi, out=wb)
            np.less_equal(vb, wb, out=tb)
            ib &= tb
            np.multiply(zp, lo, out=wb)
            np.greater_equal(vb, wb, out=tb)
            ib &= tb
        idx = np.flatnonzero(kb)
        if not idx.size:
            continue
        zk = zb[idx]
        check = idx if antialias else idx[~ib[idx] | data.faint[start + idx]]
        check = check if peak else check[:0]
        if check.size:
            p = np.empty((check.size, 3), np.float32)
            for axis in range(2):
                p[:, axis] = _row_at(data.xyz, start + check, r[axis], t[axis])
            p[:, 2] = zb[check]
            kb[check[~peak_keeps(p, start + check, data, camera, antialias, scale)]] = False
            ok = kb[idx]
            idx, zk = idx[ok], zk[ok]
        out_idx.append((idx + start).astype(np.uint32))
        out_z.append(zk)
    if not out_idx:
        return np.zeros(0, np.uint32), np.zeros(0, np.float32)
    return np.concatenate(out_idx), np.concatenate(out_z)


def plane_constants(frustum: Frustum, scale: float = 1.0) -> np.ndarray:
    """(2, 6) float32 per image axis (x, y) of ``frustum``'s side planes
    (:func:`splatgl.cameras.view.frustum_of`): ``a_hi, b_hi, a_lo, b_lo, lo, hi``.  A splat at
    camera-space ``(v, z)`` on that axis with world radius ``rad`` passes the side planes when
    ``v <= (rad * b_hi) + (z * a_hi)`` and ``v >= (rad * b_lo) + (z * a_lo)`` (float32, in that
    order: :func:`cull_visible`'s rearranged plane test); its centre projects inside the image
    when ``v <= z * hi`` and ``v >= z * lo``.  For an orthographic box (CullKind.BOX) z is
    replaced by 1 (``1 * a`` is ``a``): the box's edges, widened by the radius and the margin."""
    out = np.empty((2, 6), np.float32)
    if frustum.kind is CullKind.BOX:   # the box's edges, z's factor 1: v <= rad scale + hi + m / f
        for axis, (f, lo, hi) in enumerate(frustum.edges):
            out[axis] = (hi + MARGIN_PX / f, scale, lo - MARGIN_PX / f, -scale, lo, hi)
        return out
    for axis, ((f, _lo, _hi), (lo, n_lo, hi, n_hi)) in enumerate(zip(frustum.edges, frustum.sides)):
        out[axis] = (hi + n_hi * MARGIN_PX / f, n_hi * scale, lo - n_lo * MARGIN_PX / f,
                     -n_lo * scale, lo, hi)
    return out


def peak_constants32(camera: Camera) -> np.ndarray:
    """(8,) float32 per-view constants of :func:`peak_keeps`: fx, fy, cx, cy, width, height and
    the Jacobian's clamps on x/z and y/z (``JACOBIAN_CLAMP tan_half_fov``, rounded once from
    float64; shaders/order_cull.comp's ``u_focal``, ``u_image``)."""
    tx, ty = (1.0, 1.0) if camera.is_orthographic else camera.tan_half_fov
    return np.array([camera.fx, camera.fy, camera.cx, camera.cy, camera.width, camera.height,
                     JACOBIAN_CLAMP * tx, JACOBIAN_CLAMP * ty], np.float32)


#: log(sqrt(AA_MIN_FACTOR)) in float32: the floor of the log of the antialiasing factor.
AA_LOG_FLOOR = np.float32(0.5 * np.log(AA_MIN_FACTOR))


def peak_keeps(p: np.ndarray, rows: np.ndarray, data: "CullData", camera: Camera,
               antialias: bool, scale: float) -> np.ndarray:
    """(K,) bool: the splats ``rows`` of ``data`` at camera-space float32 points ``p`` (K, 3)
    that the peak alpha bound keeps: :func:`peak_alpha_bound` not below 1/255, decided in
    float32 by operations IEEE 754 rounds exactly (``+ - * /``, rounding to integers, no
    transcendental, no fused multiply-add), so shaders/order_cull.comp's ``peak_keeps`` makes
    the same decision bit for bit (the device order keeps the CPU's splats, and early
    termination's batches are the CPU's).  ``o exp(-d^2 / (2 lambda)) aa >= 1/255`` is
    ``d^2 / 2 <= lambda (log(255 o) + log aa)``, with ``log(255 o)`` the cull data's
    ``cut_log`` (float32, once per scene) and ``log aa <= max(-a - a^2 / 2, log sqrt(AA_MIN))``
    (``a = LOW_PASS / lambda``; ``log(1 - a) <= -a - a^2 / 2``), the bound's factor.  It equals
    the float64 test up to float32 rounding (splats within it of the cut draw nothing); a NaN
    side keeps the splat."""
    f32 = np.float32
    c = peak_constants32(camera)
    fx, fy, cx, cy, w, h, clx, cly = (f32(v) for v in c)
    x, y, z = (np.ascontiguousarray(p[:, i], np.float32) for i in range(3))
    fx2, fy2 = fx * fx, fy * fy
    with np.errstate(all="ignore"):
        if camera.is_orthographic:
            jf2 = np.full_like(z, fx2 + fy2)
            u, v = fx * x + cx, fy * y + cy
        else:
            xz, yz = x / z, y / z
            xc, yc = np.clip(xz, -clx, clx), np.clip(yz, -cly, cly)
            jf2 = (fx2 * (f32(1) + xc * xc) + fy2 * (f32(1) + yc * yc)) / (z * z)
            u, v = fx * xz + cx, fy * yz + cy
        ms = data.max_scale[rows] * f32(scale)
        lam = jf2 * ms * ms + f32(LOW_PASS)
        nu = np.clip(np.rint(u - f32(0.5)), f32(0), w - f32(1)) + f32(0.5)
        nv = np.clip(np.rint(v - f32(0.5)), f32(0), h - f32(1)) + f32(0.5)
        du, dv = u - nu, v - nv
        lhs = f32(0.5) * (du * du + dv * dv)
        level = data.cut_log[rows]
        if antialias:
            a = f32(LOW_PASS) / lam
            level = level + np.maximum(-(a + f32(0.5) * a * a), AA_LOG_FLOOR)
        rhs = level * lam
        return ~(lhs > rhs)


def view_axis(xyz: np.ndarray, start: int, stop: int, r: np.ndarray, t, out: np.ndarray,
         tmp: np.ndarray) -> None:
    """``out = r . p + t`` for the block ``start:stop`` of (3, N) points (one camera axis)."""
    np.multiply(xyz[0, start:stop], r[0], out=out)
    np.multiply(xyz[1, start:stop], r[1], out=tmp)
    out += tmp
    np.multiply(xyz[2, start:stop], r[2], out=tmp)
    out += tmp
    out += t


def _row_at(xyz: np.ndarray, idx: np.ndarray, r: np.ndarray, t) -> np.ndarray:
    """``r . p + t`` (one camera axis) for the points ``idx`` of (3, N) points."""
    return xyz[0, idx] * r[0] + xyz[1, idx] * r[1] + xyz[2, idx] * r[2] + t
