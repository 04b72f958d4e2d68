"""Projections by angle: fisheye and equirectangular (NumPy twin of ``shaders/lib/lens.glsl``).

EWA splatting linearises the projection at each splat's centre, so a new camera model changes
two things only: where the centre lands (:func:`project_lens`) and the 2x3 Jacobian of that map
(:func:`jacobian_lens`).  Everything downstream (the 2D covariance, conic, extent, blending)
stays the same.  Both models see behind the camera plane, so they do not cull on view z:

- visibility (:func:`lens_visible`): distance ``R = |p| > near``; a fisheye also culls centres
  more than :data:`~splatgl.constants.FISHEYE_THETA_MARGIN` beyond the largest angle from the
  axis that reaches the image (:func:`fisheye_theta_limit`), never beyond
  :data:`~splatgl.constants.FISHEYE_THETA_CAP` (the projection folds at the antipode);
- depth (:func:`view_depth`): the distance ``R`` from the camera centre, for the sort and for
  the depth layer.  Along one pixel's ray, distance and view z order points the same way; for
  two splats whose centres lie in different directions they can differ, as z and the true
  per-pixel depth already do for a pinhole camera (the sort is per splat, not per pixel).

Formulas (camera space, OpenCV axes; fisheye as in OpenCV's ``cv::fisheye`` and gsplat's
fisheye camera; fx, fy in pixels per radian):

Fisheye: ``rho = sqrt(x^2 + y^2)``, ``theta = atan2(rho, z)``, ``g(theta) = theta (1 + k1
theta^2 + k2 theta^4 + k3 theta^6 + k4 theta^8)``, ``s = g / rho``, ``u = fx s x + cx``,
``v = fy s y + cy``.  With ``R^2 = rho^2 + z^2`` and ``c2 = (g' z / R^2 - s) / rho^2``:
``J = [[fx (s + x^2 c2), fx x y c2, -fx x g' / R^2], [fy x y c2, fy (s + y^2 c2), -fy y g' / R^2]]``.
Near the axis (``rho < FISHEYE_SERIES_RHO z``) ``s`` and ``c2`` cancel; their series
``s = (1 + (k1 - 1/3) t) / z`` and ``c2 = (2 k1 - 2/3) / z^3`` (``t = rho^2 / z^2``) are used.

Equirectangular: ``lon = atan2(x, z)``, ``lat = atan2(y, r)`` with ``r = sqrt(x^2 + z^2)``,
``u = fx lon + cx``, ``v = fy lat + cy``;
``J = [[fx z / r^2, 0, -fx x / r^2], [-fy x y / (R^2 r), fy r / R^2, -fy z y / (R^2 r)]]``.
At the poles ``r -> 0`` and the longitude row grows without bound: every longitude is within
reach.  ``r`` is floored at ``EQUIRECT_POLE_EPS R`` (a finite, enormous width), and every splat
is clipped to half a turn on either side of its centre (:func:`wrap_period`), so a splat at a
pole becomes a band across the whole image, once.  A splat near the +-180 degree seam is drawn
twice, at ``u`` and at ``u -+ 2 pi fx`` (:func:`wrap_copies`); with the half-turn clip the two
copies never cover the same pixel.
"""

from __future__ import annotations

import math

import numpy as np

from .camera import Camera, Projection
from ..constants import (ALPHA_MIN, EQUIRECT_POLE_EPS, FISHEYE_SERIES_RHO, FISHEYE_THETA_CAP,
                         FISHEYE_THETA_MARGIN)
from ..errors import CameraError


def fisheye_theta_d(theta: np.ndarray, k: tuple[float, float, float, float]) -> np.ndarray:
    """OpenCV fisheye ``theta_d = theta (1 + k1 theta^2 + k2 theta^4 + k3 theta^6 + k4 theta^8)``."""
    t2 = theta * theta
    return theta * (1 + t2 * (k[0] + t2 * (k[1] + t2 * (k[2] + t2 * k[3]))))


def fisheye_theta_d_prime(theta: np.ndarray, k: tuple[float, float, float, float]) -> np.ndarray:
    """Derivative ``d theta_d / d theta = 1 + 3 k1 theta^2 + 5 k2 theta^4 + 7 k3 theta^6 + 9 k4 theta^8``."""
    t2 = theta * theta
    return 1 + t2 * (3 * k[0] + t2 * (5 * k[1] + t2 * (7 * k[2] + t2 * 9 * k[3])))


def fisheye_theta_limit(camera: Camera) -> float:
    """Largest angle from the optical axis (radians) at which a fisheye keeps splat centres.

    The image corner farthest from the principal point, in normalised units, is a distorted
    angle ``theta_d``; the smallest ``theta`` that reaches it (on a 1e-4 rad grid, refined by
    bisection) plus :data:`FISHEYE_THETA_MARGIN`, capped at :data:`FISHEYE_THETA_CAP`.
    """
    corners_u = np.array([0.0, camera.width]) - camera.cx
    corners_v = np.array([0.0, camera.height]) - camera.cy
    r_max = math.sqrt(np.max(corners_u ** 2) / camera.fx ** 2 + np.max(corners_v ** 2) / camera.fy ** 2)
    grid = np.linspace(0.0, math.pi, 31417)
    reach = np.flatnonzero(fisheye_theta_d(grid, camera.distortion) >= r_max)
    if reach.size == 0:
        theta = math.pi
    else:
        hi = grid[reach[0]]
        lo = grid[max(reach[0] - 1, 0)]
        for _ in range(40):
            mid = 0.5 * (lo + hi)
            if fisheye_theta_d(np.float64(mid), camera.distortion) >= r_max:
                hi = mid
            else:
                lo = mid
        theta = hi
    return float(min(theta + FISHEYE_THETA_MARGIN, FISHEYE_THETA_CAP))


def eye_space(p_cam: np.ndarray, camera: Camera) -> np.ndarray:
    """Omni-directional stereo: (N, 3) points relative to the eye that sees each of them.

    The eyes sit on a circle of radius ``r = |ods_eye|`` in the camera's horizontal (x, z)
    plane.  A point at horizontal distance ``D`` and longitude ``a`` is seen along the ray
    tangent to that circle, of longitude ``phi = a - asin(ods_eye / D)``, from the eye
    ``e = ods_eye (cos phi, 0, -sin phi)`` (``p - e`` then has longitude ``phi``; points inside
    the circle, ``D <= r``, are seen from the tangent point at ``D = r``).  The offset is taken
    at the splat's centre and held constant across the splat.  No-op for other cameras.
    """
    eye = camera.ods_eye
    if not eye:
        return p_cam
    dt = p_cam.dtype.type
    x, z = p_cam[:, 0], p_cam[:, 2]
    d = np.maximum(np.sqrt(x * x + z * z), dt(abs(eye)))
    phi = np.arctan2(x, z) - np.arcsin(dt(eye) / d)
    out = p_cam.copy()
    out[:, 0] -= dt(eye) * np.cos(phi)
    out[:, 2] += dt(eye) * np.sin(phi)
    return out


def view_depth(p_cam: np.ndarray, camera: Camera) -> np.ndarray:
    """(N,) sort and depth-layer key: view z (pinhole, orthographic) or distance |p| (lens)."""
    if camera.is_lens:
        return np.sqrt(np.einsum("ni,ni->n", p_cam, p_cam))
    return p_cam[:, 2]


def lens_visible(p_cam: np.ndarray, camera: Camera, near: float | np.floating) -> np.ndarray:
    """(N,) bool: distance beyond ``near`` and, for a fisheye, within the angle limit."""
    dist = view_depth(p_cam, camera)
    keep = dist > near
    if camera.projection is Projection.FISHEYE:
        dt = p_cam.dtype.type
        rho = np.hypot(p_cam[:, 0], p_cam[:, 1])
        keep &= np.arctan2(rho, p_cam[:, 2]) <= dt(fisheye_theta_limit(camera))
    return keep


def _fisheye_s_c2(p: np.ndarray, k) -> tuple[np.ndarray, ...]:
    """``(rho, theta, s, c2, g')`` of the fisheye map (series near the axis)."""
    dt = p.dtype.type
    x, y, z = p[:, 0], p[:, 1], p[:, 2]
    rho2 = x * x + y * y
    rho = np.sqrt(rho2)
    r2 = rho2 + z * z
    theta = np.arctan2(rho, z)
    g = fisheye_theta_d(theta, k)
    gp = fisheye_theta_d_prime(theta, k)
    near_axis = rho < dt(FISHEYE_SERIES_RHO) * z
    with np.errstate(divide="ignore", invalid="ignore"):
        s_far = g / rho
        c2_far = (gp * z / r2 - s_far) / rho2
        zs = np.where(near_axis, z, dt(1.0))
        t = rho2 / (zs * zs)
        s_near = (dt(1.0) + (dt(k[0]) - dt(1.0 / 3.0)) * t) / zs
        c2_near = (dt(2.0) * dt(k[0]) - dt(2.0 / 3.0)) / (zs * zs * zs)
    return (rho, theta, np.where(near_axis, s_near, s_far), np.where(near_axis, c2_near, c2_far),
            gp, r2)


def project_lens(p_cam: np.ndarray, camera: Camera) -> np.ndarray:
    """(N, 3) camera-space points -> (N, 2) pixel coordinates for a fisheye or equirect camera."""
    dt = p_cam.dtype.type
    fx, fy, cx, cy = (dt(v) for v in (camera.fx, camera.fy, camera.cx, camera.cy))
    x, y, z = p_cam[:, 0], p_cam[:, 1], p_cam[:, 2]
    if camera.projection is Projection.FISHEYE:
        _, _, s, _, _, _ = _fisheye_s_c2(p_cam, camera.distortion)
        return np.stack([fx * s * x + cx, fy * s * y + cy], -1)
    r = np.sqrt(x * x + z * z)
    return np.stack([fx * np.arctan2(x, z) + cx, fy * np.arctan2(y, r) + cy], -1)


def jacobian_lens(p_cam: np.ndarray, camera: Camera) -> np.ndarray:
    """(N, 2, 3) Jacobian of :func:`project_lens` at ``p_cam`` (formulas in the module doc)."""
    dt = p_cam.dtype.type
    fx, fy = dt(camera.fx), dt(camera.fy)
    x, y, z = p_cam[:, 0], p_cam[:, 1], p_cam[:, 2]
    j = np.zeros((p_cam.shape[0], 2, 3), p_cam.dtype)
    if camera.projection is Projection.FISHEYE:
        _, _, s, c2, gp, r2 = _fisheye_s_c2(p_cam, camera.distortion)
        j[:, 0, 0] = fx * (s + x * x * c2)
        j[:, 0, 1] = fx * x * y * c2
        j[:, 0, 2] = -fx * x * gp / r2
        j[:, 1, 0] = fy * x * y * c2
        j[:, 1, 1] = fy * (s + y * y * c2)
        j[:, 1, 2] = -fy * y * gp / r2
        return j
    big_r2 = x * x + y * y + z * z
    r = np.maximum(np.sqrt(x * x + z * z), dt(EQUIRECT_POLE_EPS) * np.sqrt(big_r2))
    j[:, 0, 0] = fx * z / (r * r)
    j[:, 0, 2] = -fx * x / (r * r)
    j[:, 1, 0] = -fy * x * y / (big_r2 * r)
    j[:, 1, 1] = fy * r / big_r2
    j[:, 1, 2] = -fy * z * y / (big_r2 * r)
    return j


def wrap_period(camera: Camera) -> float | None:
    """Pixels per full turn of longitude (``2 pi fx``) for an equirectangular camera, else None.

    Every splat of such a camera is clipped to ``|x - u| <= period / 2``.
    """
    if camera.projection is not Projection.EQUIRECTANGULAR:
        return None
    return 2.0 * math.pi * camera.fx


#: Screen margin (pixels) of the equirect seam test: a splat whose reach comes this close to
#: the seam is drawn on both sides.
SEAM_MARGIN_PX = 4.0


def wrap_copies(p_cam: np.ndarray, radius: np.ndarray, camera: Camera) -> np.ndarray:
    """(N,) bool: equirect splats that may reach across the +-180 degree seam (drawn twice).

    The seam is the half plane ``x = 0, z < 0``.  A splat of world radius ``radius`` (its
    opacity-aware reach plus a pixel margin) can touch it only if ``|x| < radius`` and
    ``z < radius``; that bound also holds every splat near a pole.
    """
    if camera.projection is not Projection.EQUIRECTANGULAR:
        return np.zeros(p_cam.shape[0], bool)
    dist = np.sqrt(np.einsum("ni,ni->n", p_cam, p_cam).astype(np.float64))
    reach = radius.astype(np.float64) + SEAM_MARGIN_PX * dist / camera.fx
    return (np.abs(p_cam[:, 0]) < reach) & (p_cam[:, 2] < reach)


def wrap_shift(mean_u: np.ndarray, camera: Camera) -> np.ndarray:
    """(N,) shift in pixels of the second copy of a seam splat: towards the other edge."""
    period = wrap_period(camera)
    return np.where(mean_u < camera.cx, period, -period).astype(mean_u.dtype)


#: Top bit of a sorted index: the entry is the second copy of a seam splat (``shaders/lib/
#: splat_setup.glsl`` decodes it).
WRAP_FLAG = np.uint32(0x80000000)


def projection_defines(camera: Camera) -> dict[str, object]:
    """Shader specialisation for the camera's projection (ORTHOGRAPHIC, FISHEYE or EQUIRECT)."""
    return {Projection.ORTHOGRAPHIC: {"ORTHOGRAPHIC": 1}, Projection.FISHEYE: {"FISHEYE": 1},
            Projection.EQUIRECTANGULAR: {"EQUIRECT": 1}}.get(camera.projection, {})


def lens_uniforms(camera: Camera) -> dict[str, object]:
    """Values of the lens uniforms of ``shaders/lib/camera.glsl`` (zeros where unused)."""
    fisheye = camera.projection is Projection.FISHEYE
    return {
        "u_distortion": tuple(camera.distortion),
        "u_theta_limit": fisheye_theta_limit(camera) if fisheye else 0.0,
        "u_wrap_period": wrap_period(camera) or 0.0,
        "u_ods_eye": camera.ods_eye,
    }


def lens_order(p_cam: np.ndarray, keep: np.ndarray, radius: np.ndarray, camera: Camera
               ) -> tuple[np.ndarray, np.ndarray]:
    """Sort inputs of a lens camera's kept splats: ``(depths (M,), indices (M,) uint32)``.

    ``keep``: (K,) indices of the kept splats; ``radius``: (K,) their world reach.  Depth is
    the distance; seam splats of an equirectangular camera appear twice, the copy with
    :data:`WRAP_FLAG` set in its index and the same depth.
    """
    pk = eye_space(p_cam[keep], camera)
    depth = view_depth(pk, camera).astype(np.float32)
    idx = keep.astype(np.uint32)
    dup = wrap_copies(pk, radius, camera)
    if dup.any():
        depth = np.concatenate([depth, depth[dup]])
        idx = np.concatenate([idx, idx[dup] | WRAP_FLAG])
    return depth, idx


def lens_cull(p_cam: np.ndarray, opacities: np.ndarray, camera: Camera, near: float) -> np.ndarray:
    """(N,) bool keep mask of a lens camera: :func:`lens_visible` and opacity >= 1/255.

    (No screen test: a fisheye or panorama sees most of a scene; the rasterizer drops the rest.)
    """
    return lens_visible(eye_space(p_cam, camera), camera, near) & (opacities >= ALPHA_MIN)


def splat_reach(max_scale: np.ndarray, opacities: np.ndarray) -> np.ndarray:
    """(N,) world radius within which a splat can reach alpha 1/255: ``k max_scale`` with the
    opacity-aware sigma count ``k = sqrt(2 ln(255 o))`` (at most ~3.33)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        k = np.sqrt(np.maximum(2.0 * np.log(np.maximum(opacities, 1e-30) / ALPHA_MIN), 0.0))
    return (k * max_scale).astype(np.float64)


def require_support(camera: Camera, surfel: bool, renderer: str, equirect: bool = True) -> None:
    """Raise :class:`~splatgl.errors.CameraError` where ``renderer`` cannot draw ``camera``.

    2DGS surfels intersect each pixel's ray with the splat's plane through the pinhole matrix,
    which the angle projections do not have; the tile renderer has no seam copies, so no
    equirectangular images (``equirect=False``).
    """
    if not camera.is_lens:
        return
    if surfel:
        raise CameraError(f"{camera.projection.value} cameras render 3DGS scenes only; this "
                          "scene holds 2DGS surfels (use a perspective or orthographic camera)")
    if not equirect and camera.projection is Projection.EQUIRECTANGULAR:
        raise CameraError(f"the {renderer} renderer cannot draw equirectangular images; use "
                          "--renderer quad or reference")


def check_fov_applies(projection: Projection | str, fov_degrees: float | None) -> None:
    """Raise :class:`CameraError` for a field of view given to a projection without one:
    equirectangular (always 360 x 180 degrees) or orthographic (pixels per world unit)."""
    projection = Projection(projection)
    if fov_degrees is not None and projection in (Projection.EQUIRECTANGULAR, Projection.ORTHOGRAPHIC):
        what = ("an equirectangular panorama always spans 360 x 180 degrees"
                if projection is Projection.EQUIRECTANGULAR else
                "an orthographic camera has no field of view (its scale is pixels per world unit)")
        raise CameraError(f"--fov {fov_degrees:g} does not apply: {what}")


def with_projection(camera: Camera, projection: Projection | str, fov_degrees: float | None = None
                    ) -> Camera:
    """``camera``'s pose and image size with another projection (the CLI's ``--projection``).

    Fisheye: ``fov_degrees`` (default 180) across the image circle of diameter
    ``min(W, H)``; equirectangular: the full panorama; perspective: ``fov_degrees`` vertical
    (default: unchanged for a perspective camera, else 50); orthographic: unchanged scale.
    A field of view for a projection without one is refused (:func:`check_fov_applies`).
    """
    projection = Projection(projection)
    check_fov_applies(projection, fov_degrees)
    w, h, pose = camera.width, camera.height, camera.world_to_camera
    if projection is camera.projection and fov_degrees is None:
        return camera
    if projection is Projection.FISHEYE:
        return Camera.fisheye(w, h, 180.0 if fov_degrees is None else fov_degrees, pose)
    if projection is Projection.EQUIRECTANGULAR:
        return Camera.equirectangular(w, h, pose)
    if projection is Projection.PERSPECTIVE:
        return Camera.from_fov(w, h, 50.0 if fov_degrees is None else fov_degrees, pose)
    return Camera(w, h, camera.fx, camera.fy, camera.cx, camera.cy, pose, projection)


def replaces_intrinsics(camera: Camera, projection: Projection | str | None,
                        fov_degrees: float | None) -> bool:
    """Whether :func:`with_projection` builds new intrinsics for ``camera`` (keeping only its
    pose): another fisheye, equirectangular or perspective model, or a field of view."""
    target = camera.projection if projection is None else Projection(projection)
    if target is Projection.ORTHOGRAPHIC:
        return False
    return target is not camera.projection or fov_degrees is not None


def adapt_camera(camera: Camera, width: int | None = None, height: int | None = None,
                 projection: Projection | str | None = None, fov_degrees: float | None = None,
                 source: str = "the camera") -> Camera:
    """A camera read from a file, at the asked image size and projection (``--camera`` with
    ``--width``, ``--height``, ``--projection``, ``--fov``; :func:`splatgl.load_camera`).

    - Its own intrinsics (no other projection, no field of view): ``width`` and/or ``height``
      scale them; one of the two keeps the file's aspect, both must keep it.
    - New intrinsics (:func:`replaces_intrinsics`: e.g. a fisheye or panorama from a pinhole
      file): only the pose is the file's, and any ``width`` x ``height`` is allowed.  A
      missing side follows the file's aspect, or 2:1 for an equirectangular panorama, whose
      height defaults to the file's.

    ``source`` (the file's name) appears in messages.

    Raises:
        CameraError: both sides given in another aspect than the file's own intrinsics; a field
            of view the projection has none of (see :func:`with_projection`).
    """
    w, h = width, height
    if not replaces_intrinsics(camera, projection, fov_degrees):
        if w and h and w != round(camera.width * h / camera.height) \
                and h != round(camera.height * w / camera.width):
            raise CameraError(
                f"--width {w} --height {h} would stretch {source}'s {camera.width}x{camera.height} "
                f"view (aspect {camera.width / camera.height:.4g}, asked {w / h:.4g}); give only "
                "one of them to scale keeping the aspect")
        if w or h:
            camera = camera.resized(w or max(1, round(camera.width * h / camera.height)),
                                    h or max(1, round(camera.height * w / camera.width)))
        if projection is None and fov_degrees is None:
            return camera
        return with_projection(camera, camera.projection if projection is None else projection,
                               fov_degrees)
    target = camera.projection if projection is None else Projection(projection)
    if target is Projection.EQUIRECTANGULAR:
        h = h or (max(1, round(w / 2)) if w else camera.height)
        w = w or 2 * h
    else:
        w = w or (max(1, round(camera.width * h / camera.height)) if h else camera.width)
        h = h or max(1, round(camera.height * w / camera.width))
    return with_projection(camera.resized(w, h), target, fov_degrees)  # keeps only the pose
