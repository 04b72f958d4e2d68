"""NumPy twin of the 2DGS surfel stages (``shaders/surfel.vert``, ``shaders/surfel.frag``,
``shaders/lib/surfel.glsl``; same names): ray-splat intersection of Huang et al. 2024.

A surfel has centre ``p`` (world), tangent axes ``t_u, t_v`` (the first two columns of its
rotation) and scales ``s_u, s_v``.  ``H`` maps tangent-plane coordinates ``(u, v, 1)`` to world
homogeneous coordinates (columns ``(s_u t_u, 0)``, ``(s_v t_v, 0)``, ``(p, 1)``); with the camera's
3x4 pixel projection ``P`` the 3x3 matrix ``T = P H`` maps ``(u, v, 1)`` to homogeneous pixels:

* perspective: ``P = K [R | t]``, ``K = [[fx, 0, cx], [0, fy, cy], [0, 0, 1]]``;
* orthographic (``u = fx x_c + cx``): ``P = [[fx R_0, fx t_0 + cx], [fy R_1, fy t_1 + cy],
  [0, 0, 0, 1]]`` with ``R_i``, ``t_i`` the rows of the world-to-camera transform.

A pixel centre ``x = (x, y)`` (image coordinates, centre of pixel (i, j) at ``(j + 0.5, i + 0.5)``)
defines the planes ``h_u = T_0 - x T_2`` and ``h_v = T_1 - y T_2`` (paper eq. 8-9); the tangent
point they share is ``(u, v, 1) ~ h_u x h_v`` (eq. 10, Cramer's rule).  The Gaussian value is
``G = exp(-(u^2 + v^2) / 2)`` (eq. 6); the screen-space low pass (eq. 11, the official
rasterizer) takes ``rho = min(u^2 + v^2, F |x - c|^2)`` with ``F = SURFEL_FILTER_INV_SQUARE`` and
``c`` the projected centre, and ``alpha = min(0.99, o exp(-rho / 2))``, skipped below 1/255.
A pixel's depth is the view z of its ray's hit on the surfel's plane where the surfel's own
Gaussian wins (``u^2 + v^2 <= F |x - c|^2``), else the centre's view z.  This is the rule the
official rasterizer (hbb1/diff-surfel-rasterization) used from 2023-11-24 (commit 1bc2138) to
2024-11-10 (commit e0ed020); since then it takes the hit everywhere and skips a pixel whose hit
is nearer than 0.2.  splatgl keeps the older rule on purpose: a pixel lit by the low pass alone
has a ray that misses the surfel's ellipse, and its hit can lie anywhere along a grazing ray
(measured on a random 1,500-surfel test scene of radius ~2: a hit 137 units away adding 1.8 to
a pixel of depth 3.7, where the tile renderer and the float32 reference then differ by 3.8e-4,
2.4 times the tolerance their depths otherwise meet); for a plane through
the camera centre every hit is the camera itself (z = 0, decided by rounding), which the
official rasterizer then drops with its near test, so exactly edge-on surfels vanish there
while they keep their low-pass dot here.  Where the kernel wins, the hit lies inside the
surfel's k-sigma ellipse and is well conditioned.  Pixels whose ray meets the plane behind the
camera or not at all get the low pass alone and the centre's z.

``Convention.GSPLAT`` follows gsplat's 2DGS rules instead (:func:`gsplat_screen`,
:func:`surfel_alpha`): the low pass is centred on gsplat's ``means2d``, the centre of the image
of the 1-sigma ellipse (not the projected centre: they differ under perspective), tile radii
are ``ceil(3.33 sqrt(max(1e-4, e^2)))`` per axis with ``e`` the 1-sigma half extents, depth is
the centre's view z, and there is no per-pixel near test (only a ray parallel to the plane is
skipped); alpha clamp 0.999 and the inclusive stop as for 3DGS.

Numerics: every path works in the *centred* frame, ``T' = A T`` with ``A`` translating pixel
coordinates by ``-c`` (so ``x - c`` replaces ``x``): then ``T'_02 = T'_12 = 0`` exactly, the
bounding-box formula has no cancelling terms and ``h_u = T'_0 - (x - c_x) T_2`` keeps its
precision far from the principal point.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..cameras.camera import Camera
from ..constants import ALPHA_MAX, ALPHA_MIN, GSPLAT_SURFEL_MIN_EXTENT_SQ, SURFEL_FILTER_INV_SQUARE
from .project import quat_to_rotmat, to_camera
from ..scene.settings import Convention


def camera_axes(means: np.ndarray, rotations: np.ndarray, scales: np.ndarray,
                camera: Camera) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Camera-space columns of ``W H``: ``(a_u, a_v, p_cam)``, each (N, 3) in the input dtype.

    ``a_u = R_cw (s_u t_u)``, ``a_v = R_cw (s_v t_v)`` (world units scaled into camera space),
    ``p_cam = R_cw p + t_cw``.  means (N, 3) world, rotations (N, 4) (w, x, y, z), scales (N, 2).
    """
    dt = means.dtype
    rot = quat_to_rotmat(rotations.astype(dt))
    w = camera.rotation.astype(dt)
    a_u = (rot[:, :, 0] * scales[:, 0:1].astype(dt)) @ w.T
    a_v = (rot[:, :, 1] * scales[:, 1:2].astype(dt)) @ w.T
    return a_u, a_v, to_camera(means, camera)


def surfel_transform(means: np.ndarray, rotations: np.ndarray, scales: np.ndarray,
                     camera: Camera) -> np.ndarray:
    """(N, 3, 3) ``T = P H``: row r of ``T[k]`` is ``T_r``, so ``T (u, v, 1) = w (x, y, 1)``.

    Pixels as in the module docstring; perspective ``w`` is the camera z, orthographic ``w = 1``.
    """
    a_u, a_v, p = camera_axes(means, rotations, scales, camera)
    cols = np.stack([a_u, a_v, p], axis=-1)            # (N, 3, 3): W H without the last row
    dt = means.dtype.type
    fx, fy, cx, cy = (dt(v) for v in (camera.fx, camera.fy, camera.cx, camera.cy))
    t = np.empty_like(cols)
    if camera.is_orthographic:
        t[:, 0] = fx * cols[:, 0]
        t[:, 1] = fy * cols[:, 1]
        t[:, 0, 2] += cx
        t[:, 1, 2] += cy
        t[:, 2] = np.array([0.0, 0.0, 1.0], means.dtype)
    else:
        t[:, 0] = fx * cols[:, 0] + cx * cols[:, 2]
        t[:, 1] = fy * cols[:, 1] + cy * cols[:, 2]
        t[:, 2] = cols[:, 2]
    return t


@dataclass(frozen=True)
class SurfelScreen:
    """Per-surfel screen data, the vertex stage's outputs (N rows, the input dtype).

    Attributes:
        center: (N, 2) projected centre ``c`` in pixels (low-pass centre).
        rows: (N, 3, 3) centred ``T' = A T``: rows ``T'_0, T'_1`` (third entries 0) and ``T_2``.
        depth_row: (N, 3) camera z of ``(u, v, 1)``: ``z = depth_row . (u, v, 1)``.
        view_z: (N,) camera z of the centre (the sort and near-cull key).
    """

    center: np.ndarray
    rows: np.ndarray
    depth_row: np.ndarray
    view_z: np.ndarray


def surfel_screen(means: np.ndarray, rotations: np.ndarray, scales: np.ndarray,
                  camera: Camera) -> SurfelScreen:
    """The centred transform of each surfel (see :class:`SurfelScreen`), no culling.

    Perspective, with ``m = p_cam.xy / p_cam.z``: ``c = f m + (cx, cy)``,
    ``T'_0 = fx (a_u.x - m.x a_u.z, a_v.x - m.x a_v.z, 0)`` (likewise ``T'_1`` with y),
    ``T_2 = (a_u.z, a_v.z, p_cam.z)``.  Orthographic: ``c = f p_cam.xy + (cx, cy)``,
    ``T'_0 = fx (a_u.x, a_v.x, 0)``, ``T'_1 = fy (a_u.y, a_v.y, 0)``, ``T_2 = (0, 0, 1)``.
    """
    a_u, a_v, p = camera_axes(means, rotations, scales, camera)
    dt = means.dtype.type
    f = np.array([camera.fx, camera.fy], means.dtype)
    principal = np.array([camera.cx, camera.cy], means.dtype)
    n = means.shape[0]
    rows = np.zeros((n, 3, 3), means.dtype)
    depth_row = np.stack([a_u[:, 2], a_v[:, 2], p[:, 2]], axis=-1)
    if camera.is_orthographic:
        center = f * p[:, :2] + principal
        for r in range(2):
            rows[:, r, 0] = f[r] * a_u[:, r]
            rows[:, r, 1] = f[r] * a_v[:, r]
        rows[:, 2, 2] = dt(1.0)
    else:
        with np.errstate(divide="ignore", invalid="ignore"):
            m = p[:, :2] / p[:, 2:3]
        center = f * m + principal
        for r in range(2):
            rows[:, r, 0] = f[r] * (a_u[:, r] - m[:, r] * a_u[:, 2])
            rows[:, r, 1] = f[r] * (a_v[:, r] - m[:, r] * a_v[:, 2])
        rows[:, 2] = depth_row
    return SurfelScreen(center, rows, depth_row, p[:, 2])


def sigma_count(opacities: np.ndarray) -> np.ndarray:
    """(N,) ``k = sqrt(2 ln(255 o))``: beyond ``u^2 + v^2 = k^2``, ``o G < 1/255`` (0 if o <= 1/255)."""
    dt = opacities.dtype.type
    with np.errstate(divide="ignore", invalid="ignore"):
        k2 = dt(2.0) * np.log(opacities / dt(ALPHA_MIN))
    return np.sqrt(np.maximum(np.nan_to_num(k2, nan=0.0), dt(0.0)))


@dataclass(frozen=True)
class SurfelBounds:
    """Screen boxes of surfels (N rows), pixels, clamped to the image ``[0, W] x [0, H]``.

    Attributes:
        center: (N, 2) box centre.  half: (N, 2) half extents (x, y); ``center +- half`` is the
            box.  Zero for invisible rows.
        bounded: (N,) the k-ellipse lies in front of the near plane (always, orthographic);
            otherwise the box is the whole image.
        visible: (N,) finite, non-empty box and ``o > 1/255``.
    """

    center: np.ndarray
    half: np.ndarray
    bounded: np.ndarray
    visible: np.ndarray


def ellipse_image(rows: np.ndarray, k2: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Centre and squared half extents of the image of the ellipse ``u^2 + v^2 = k^2``.

    ``rows``: (N, 3, 3) centred ``T'`` (third entries of rows 0-1 zero); ``k2``: (N,) or scalar.
    The ellipse is the conic ``diag(1, 1, -k^2)``; its image has the dual conic
    ``C* = T' diag(k^2, k^2, -1) T'^T``, whose centre is ``x_c = C*_r2 / C*_22`` and whose
    tangent lines ``x_r = x_c +- sqrt(x_c^2 - C*_rr / C*_22)`` bound it.  Returns
    ``(x_c (N, 2) relative to the projected centre, x_c^2 - C*_rr / C*_22 (N, 2), C*_22 (N,))``
    (NaN/Inf where ``C*_22 = 0``; callers mask).  ``C*_22 = k^2 |T_2.xy|^2 - T_22^2``.
    """
    t2 = rows[:, 2]
    c22 = k2 * (t2[:, 0] * t2[:, 0] + t2[:, 1] * t2[:, 1]) - t2[:, 2] * t2[:, 2]
    xc = np.empty(rows.shape[:1] + (2,), rows.dtype)
    half_sq = np.empty_like(xc)
    for r in range(2):
        tr = rows[:, r]
        c_rr = k2 * (tr[:, 0] * tr[:, 0] + tr[:, 1] * tr[:, 1])
        c_r2 = k2 * (tr[:, 0] * t2[:, 0] + tr[:, 1] * t2[:, 1])
        xc[:, r] = c_r2 / c22
        half_sq[:, r] = xc[:, r] * xc[:, r] - c_rr / c22
    return xc, half_sq, c22


@dataclass(frozen=True)
class GsplatScreen:
    """gsplat's 2DGS screen quantities (N rows, the input dtype).

    Attributes:
        means2d: (N, 2) centre of the image of the 1-sigma ellipse (pixels): gsplat's low-pass
            centre and tile-rectangle centre.
        extent: (N, 2) ``sqrt(max(1e-4, e^2))``, ``e`` the 1-sigma half extents (pixels).
        rows: (N, 3, 3) ``T`` centred on ``means2d`` (``T''_r = T_r - means2d_r T_2``); its
            third column is no longer zero.
        ok: (N,) ``C*_22 != 0`` and finite (gsplat drops the rest).
    """

    means2d: np.ndarray
    extent: np.ndarray
    rows: np.ndarray
    ok: np.ndarray


def gsplat_screen(screen: SurfelScreen) -> GsplatScreen:
    """gsplat's ``means2d`` and 1-sigma extents of each surfel (:func:`ellipse_image`, k = 1).

    In gsplat's own terms, with ``M = (K W H)^T`` and ``t = (1, 1, -1)``: ``d = t . (M_2 M_2)``,
    ``means2d_r = (t / d) . (M_r M_2)``, ``extent_r = sqrt(max(1e-4, means2d_r^2 - (t / d) .
    (M_r M_r)))``; the same numbers in the centred frame.
    """
    rows = screen.rows
    dt = rows.dtype.type
    with np.errstate(all="ignore"):
        xc, half_sq, c22 = ellipse_image(rows, dt(1.0))
        extent = np.sqrt(np.maximum(half_sq, dt(GSPLAT_SURFEL_MIN_EXTENT_SQ)))
        means2d = screen.center + xc
        moved = rows.copy()
        moved[:, :2] -= xc[:, :, None] * rows[:, 2:3]
    ok = (c22 != 0) & np.isfinite(means2d).all(1) & np.isfinite(extent).all(1)
    return GsplatScreen(means2d, extent, moved, ok)


def surfel_bounds(screen: SurfelScreen, opacities: np.ndarray, camera: Camera,
                  near: float) -> SurfelBounds:
    """Box of the pixels where a surfel can reach alpha 1/255 (the quad and the tile rect).

    The ellipse ``u^2 + v^2 = k^2`` (``k`` from :func:`sigma_count`) is the conic
    ``C = diag(1, 1, -k^2)``; its image has the dual conic ``C* = T' diag(k^2, k^2, -1) T'^T``
    (scaled by ``k^2``).  A vertical line ``x = X`` is tangent when
    ``C*_00 - 2 X C*_02 + X^2 C*_22 = 0``, so the x extent is ``x_c +- sqrt(x_c^2 - C*_00 / C*_22)``,
    ``x_c = C*_02 / C*_22`` (likewise y).  In the centred frame ``C*_00 = k^2 |T'_0.xy|^2 >= 0``
    and ``C*_22 = k^2 |T_2.xy|^2 - T_22^2 < 0`` whenever the ellipse is in front of the camera,
    so the root is never negative.  Perspective surfels whose k-ellipse reaches the near plane
    (``T_22 - k |T_2.xy| <= near``: the image is a parabola or hyperbola, unbounded) get the
    whole image.  The box is unioned with the low-pass disc ``|x - c| <= k / sqrt(F)`` and
    clamped to the image; NaN and empty boxes are invisible.
    """
    rows, center = screen.rows, screen.center
    dt = rows.dtype.type
    k = sigma_count(opacities.astype(rows.dtype))
    t2 = rows[:, 2]
    a2 = t2[:, 0] * t2[:, 0] + t2[:, 1] * t2[:, 1]
    with np.errstate(all="ignore"):
        xc, half_sq, _ = ellipse_image(rows, k * k)
        half = np.sqrt(np.maximum(half_sq, dt(0.0)))
        r_lp = (k / dt(np.sqrt(SURFEL_FILTER_INV_SQUARE)))[:, None]
        lo = center + np.minimum(xc - half, -r_lp)
        hi = center + np.maximum(xc + half, r_lp)
        if camera.is_orthographic:
            bounded = np.ones(k.shape, bool)
        else:
            bounded = t2[:, 2] - k * np.sqrt(a2) > dt(near)
        size = np.array([camera.width, camera.height], rows.dtype)
        lo = np.where(bounded[:, None], lo, dt(0.0))
        hi = np.where(bounded[:, None], hi, size)
        lo = np.clip(lo, dt(0.0), size)
        hi = np.clip(hi, dt(0.0), size)
        visible = (hi > lo).all(1) & np.isfinite(center).all(1) & (k > 0)
    box_c = np.where(visible[:, None], dt(0.5) * (lo + hi), dt(0.0))
    box_h = np.where(visible[:, None], dt(0.5) * (hi - lo), dt(0.0))
    return SurfelBounds(box_c, box_h, bounded, visible)


def intersect(t0: np.ndarray, t1: np.ndarray, t2: np.ndarray, dx: np.ndarray, dy: np.ndarray,
              near_test: bool = True) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Tangent-plane point ``(u, v)`` hit by the ray through pixel ``c + (dx, dy)``.

    ``t0, t1, t2``: (..., 3) rows of the centred ``T'``; ``dx, dy``: pixel offsets from the
    centre ``c`` (pixels), broadcast against ``t0[..., 0]``.  ``h_u = T'_0 - dx T_2``,
    ``h_v = T'_1 - dy T_2`` (eq. 9) and ``(u, v, 1) ~ h_u x h_v`` (eq. 10).  Returns
    ``(u, v, hit)``; ``hit`` is False where the ray is parallel to the plane (``p_z = 0``), meets
    it behind the camera (``T_2 . (u, v, 1) <= 0``; only with ``near_test``) or the values
    are not finite.
    """
    u, v, w, hit = _intersect(t0, t1, t2, dx, dy)
    if near_test:
        hit &= w > 0
    return u, v, hit


def _intersect(t0, t1, t2, dx, dy):
    """:func:`intersect`'s ``(u, v, w, hit)`` without the near test; ``w = T_2 . (u, v, 1)``
    is the hit's homogeneous w (its view z under perspective)."""
    hu = [t0[..., i] - dx * t2[..., i] for i in range(3)]
    hv = [t1[..., i] - dy * t2[..., i] for i in range(3)]
    px = hu[1] * hv[2] - hu[2] * hv[1]
    py = hu[2] * hv[0] - hu[0] * hv[2]
    pz = hu[0] * hv[1] - hu[1] * hv[0]
    with np.errstate(all="ignore"):
        u = px / pz
        v = py / pz
        w = t2[..., 0] * u + t2[..., 1] * v + t2[..., 2]
        hit = (pz != 0) & np.isfinite(u) & np.isfinite(v)
    return u, v, w, hit


def surfel_alpha(rows: np.ndarray, depth_row: np.ndarray, opacity: np.ndarray, dx: np.ndarray,
                 dy: np.ndarray, alpha_max: float = ALPHA_MAX,
                 convention: Convention = Convention.INRIA) -> tuple[np.ndarray, np.ndarray]:
    """Per-pixel alpha and depth of surfels (the fragment stage), broadcasting.

    Args:
        rows: (..., 3, 3) ``T`` centred on the low-pass centre (:class:`SurfelScreen` rows, or
            :class:`GsplatScreen` rows under GSPLAT).  depth_row: (..., 3).
        opacity: (...) opacities.  dx, dy: pixel-centre offsets from that centre, broadcast
            against ``opacity``.
        convention: INRIA (the official 2DGS rasterizer) or GSPLAT (gsplat's rules).
    Returns:
        ``alpha``: ``min(alpha_max, o exp(-rho / 2))``, ``rho = min(u^2 + v^2, F (dx^2 + dy^2))``,
        0 below 1/255.  INRIA: a ray that misses the plane or meets it behind the camera gets
        the low pass alone; GSPLAT: only a ray parallel to the plane is skipped (alpha 0), the
        hit is used wherever it lies.  ``depth``: INRIA, the view z of the hit
        ``depth_row . (u, v, 1)`` where the surfel's own Gaussian wins (``rho_3d <= rho_2d``),
        else the centre's z (see the module notes for why not the hit everywhere); GSPLAT, the
        centre's view z.
    """
    dt = rows.dtype.type
    gsplat = Convention(convention) is Convention.GSPLAT
    u, v, w, hit = _intersect(rows[..., 0, :], rows[..., 1, :], rows[..., 2, :], dx, dy)
    if not gsplat:
        hit &= w > 0
    with np.errstate(all="ignore"):
        rho3d = np.where(hit, u * u + v * v, dt(np.inf))
        rho2d = dt(SURFEL_FILTER_INV_SQUARE) * (dx * dx + dy * dy)
        rho = np.minimum(rho3d, rho2d)
        alpha = np.minimum(dt(alpha_max), opacity * np.exp(dt(-0.5) * rho))
        z_hit = depth_row[..., 0] * u + depth_row[..., 1] * v + depth_row[..., 2]
    keep = alpha >= dt(ALPHA_MIN)
    if gsplat:
        keep = keep & hit
        depth = np.broadcast_to(depth_row[..., 2], np.shape(z_hit))
    else:
        depth = np.where(rho3d <= rho2d, z_hit, depth_row[..., 2])
    return np.where(keep, alpha, dt(0.0)), depth
