"""NumPy twin of the projection stage (``shaders/lib/project.glsl``): the per-splat math.

Every function works on arrays of N splats in the dtype it is given (float64 for checks, float32
to mimic the GPU) and follows DESIGN.md section 1.  The GLSL functions carry the same names.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..cameras.camera import Camera
from ..cameras.equirect import eye_space
from ..cameras.view import anchored_camera
from ..scene.quaternion import quat_to_rotmat  # noqa: F401 (the projection's rotations; re-exported)
from ..constants import (ALPHA_MIN, DET_CANCEL_RATIO, EXTENT_DISCRIMINANT_FLOOR, EXTENT_SIGMAS,
                         LOW_PASS, AA_MIN_FACTOR, MAX_RADIUS, SH_C0, SH_C1, SH_C2, SH_C3,
                         SH_OFFSET, sh_coeff_count)


def covariance_3d(rot: np.ndarray, scales: np.ndarray) -> np.ndarray:
    """World covariance ``Sigma = R S S^T R^T``: (N, 3, 3) from (N, 3, 3) rotations, (N, 3) scales."""
    m = rot * scales[..., None, :]  # R S
    return m @ np.swapaxes(m, -1, -2)


def transform_points(points: np.ndarray, rot: np.ndarray, trans: np.ndarray) -> np.ndarray:
    """``R p + t`` for (N, 3) points, in the points' dtype.

    Written out per output column: NumPy's matmul with a 3-wide inner dimension measured ~10x
    slower here (28 ms against 3 ms for 150k float32 points).
    """
    rot = np.asarray(rot, points.dtype)
    trans = np.asarray(trans, points.dtype)
    out = np.empty(points.shape, points.dtype)
    x, y, z = points[:, 0], points[:, 1], points[:, 2]
    for i in range(3):
        out[:, i] = x * rot[i, 0] + y * rot[i, 1] + z * rot[i, 2] + trans[i]
    return out


def anchored(means: np.ndarray, anchor: np.ndarray, camera: Camera, dtype
             ) -> tuple[np.ndarray, Camera]:
    """``(means - anchor`` in ``dtype`` (the subtraction in float64), the anchored camera``)``:
    what every path projects instead of the raw world means (see :func:`anchored_camera`)."""
    rel = (np.asarray(means, np.float64) - np.asarray(anchor, np.float64)).astype(dtype)
    return rel, anchored_camera(camera, anchor)


def to_camera(means: np.ndarray, camera: Camera) -> np.ndarray:
    """(N, 3) world points -> (N, 3) camera-space points ``R_cw p + t_cw`` (OpenCV axes)."""
    return transform_points(means, camera.rotation, camera.translation)


def project_means(p_cam: np.ndarray, camera: Camera) -> np.ndarray:
    """(N, 3) camera-space points -> (N, 2) image coordinates (u, v) in pixels (the camera
    model's :meth:`~splatgl.cameras.model.CameraModel.project`)."""
    return camera.model.project(p_cam, camera)


def jacobian(p_cam: np.ndarray, camera: Camera) -> np.ndarray:
    """(N, 2, 3) EWA Jacobian of the projection at ``p_cam`` (the camera model's
    :meth:`~splatgl.cameras.model.CameraModel.jacobian`; the pinhole's clamps ``x/z`` and
    ``y/z`` to +-1.3 tan(half fov), the mean itself is not moved)."""
    return camera.model.jacobian(p_cam, camera)


def covariance_2d(cov3d: np.ndarray, p_cam: np.ndarray, camera: Camera,
                  low_pass: float = LOW_PASS) -> np.ndarray:
    """Screen covariance ``J W Sigma W^T J^T + low_pass I``: (N, 2, 2) in pixels^2."""
    w = camera.rotation.astype(cov3d.dtype)
    t = jacobian(p_cam, camera) @ w  # (N, 2, 3)
    cov = t @ cov3d @ np.swapaxes(t, -1, -2)
    cov[:, 0, 0] += low_pass
    cov[:, 1, 1] += low_pass
    return cov


def screen_factor(rot: np.ndarray, scales: np.ndarray, p_cam: np.ndarray, camera: Camera) -> np.ndarray:
    """``M = J W R S``, (N, 2, 3): the undilated screen covariance is ``M M^T`` (pixels^2)."""
    w = camera.rotation.astype(p_cam.dtype)
    return ((jacobian(p_cam, camera) @ w) @ rot) * scales[..., None, :]  # GLSL's order


def covariance_2d_det(cov2d: np.ndarray, m: np.ndarray, low_pass: float = LOW_PASS) -> np.ndarray:
    """``det(M M^T + low_pass I)`` of (N, 2, 2) covariances and their (N, 2, 3) factors, (N,).

    Guard (stress case det_nonpositive): ``a c - b^2`` of a needle 1e3 long at 45 degrees
    cancels in float32 (entries ~3e7, true det 2e7) to zero or below, and the splat vanished
    (max error 0.35).  Here ``det(M M^T)`` is the sum of the squared 2x2 minors of M
    (Cauchy-Binet), so ``det = minors + low_pass tr(M M^T) + low_pass^2 >= low_pass^2 > 0``.
    Overflow (covariances beyond ~1e19 px^2) gives +inf, hence a zero conic: a uniform veil,
    which is what such a splat is at pixel scale.  Where ``a c - b^2 > DET_CANCEL_RATIO a c``
    (no harmful cancellation) the reference's own ``a c - b^2`` is returned unchanged.
    """
    dt = m.dtype.type
    a, b, c = cov2d[:, 0, 0], cov2d[:, 0, 1], cov2d[:, 1, 1]
    with np.errstate(over="ignore", invalid="ignore"):
        plain = a * c - b * b
        accurate = plain > dt(DET_CANCEL_RATIO) * (a * c)
    r0, r1 = m[:, 0], m[:, 1]
    x, y, z = (r0[:, 1] * r1[:, 2] - r0[:, 2] * r1[:, 1], r0[:, 2] * r1[:, 0] - r0[:, 0] * r1[:, 2],
               r0[:, 0] * r1[:, 1] - r0[:, 1] * r1[:, 0])       # cross(r0, r1), as in GLSL
    with np.errstate(over="ignore", invalid="ignore"):
        minors = x * x + y * y + z * z
        trace = (r0[:, 0] * r0[:, 0] + r0[:, 1] * r0[:, 1] + r0[:, 2] * r0[:, 2]) + (
            r1[:, 0] * r1[:, 0] + r1[:, 1] * r1[:, 1] + r1[:, 2] * r1[:, 2])
        return np.where(accurate, plain, minors + dt(low_pass) * trace + dt(low_pass * low_pass))


def conic(cov2d: np.ndarray, det: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Inverse of each (N, 2, 2) covariance as (a, b, c) with ``Q = [[a, b], [b, c]]``, and det.

    ``det``: the determinant when known more accurately (:func:`covariance_2d_det`); by
    default ``a c - b^2``.  Returns ``(conic (N, 3), det (N,))``; rows with ``det <= 0`` get a
    zero conic (the reference culls them).
    """
    a, b, c = cov2d[:, 0, 0], cov2d[:, 0, 1], cov2d[:, 1, 1]
    det = a * c - b * b if det is None else det
    ok = det > 0
    inv = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0).astype(cov2d.dtype)
    return np.stack([c * inv, -b * inv, a * inv], axis=-1), det


def antialias_factor(cov2d: np.ndarray, low_pass: float = LOW_PASS) -> np.ndarray:
    """Opacity compensation ``sqrt(max(2.5e-5, det(Sigma') / det(Sigma' + 0.3 I)))``, (N,).

    ``cov2d`` is the already dilated covariance, so the undilated one is ``cov2d - low_pass I``.
    """
    a, b, c = cov2d[:, 0, 0], cov2d[:, 0, 1], cov2d[:, 1, 1]
    det_dilated = a * c - b * b
    det = (a - low_pass) * (c - low_pass) - b * b
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.where(det_dilated > 0, det / det_dilated, 0.0)
    return np.sqrt(np.maximum(AA_MIN_FACTOR, ratio)).astype(cov2d.dtype)


def eigenvalues_2d(cov2d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Reference eigenvalues ``mid +- sqrt(max(0.1, mid^2 - det))`` of (N, 2, 2) covariances."""
    mid = 0.5 * (cov2d[:, 0, 0] + cov2d[:, 1, 1])
    root = np.sqrt(np.maximum(EXTENT_DISCRIMINANT_FLOOR, discriminant(cov2d)))
    return mid + root, mid - root


def discriminant(cov2d: np.ndarray) -> np.ndarray:
    """``mid^2 - det`` of (N, 2, 2) covariances, the reference's form.

    Guard (stress case near_tiny): beyond ~1e19 px^2 both terms overflow float32 and
    ``inf - inf`` is NaN, which made the extent garbage and dropped the splat (max error
    0.26); there the equal ``((a - c) / 2)^2 + b^2`` is used (it may be +inf, never NaN).
    """
    a, b, c = cov2d[:, 0, 0], cov2d[:, 0, 1], cov2d[:, 1, 1]
    mid = 0.5 * (a + c)
    with np.errstate(over="ignore", invalid="ignore"):
        disc = mid * mid - (a * c - b * b)
        half = 0.5 * (a - c)
        return np.where(np.isfinite(disc), disc, half * half + b * b)


def reference_radius(cov2d: np.ndarray) -> np.ndarray:
    """Reference extent ``ceil(3 sqrt(lambda_max))`` in pixels, (N,) int64 (<= MAX_RADIUS)."""
    lam_max, _ = eigenvalues_2d(cov2d)
    r = np.ceil(EXTENT_SIGMAS * np.sqrt(np.maximum(lam_max, 0.0)))
    return np.minimum(r, MAX_RADIUS).astype(np.int64)


def ellipse_axes(cov2d: np.ndarray, opacities: np.ndarray, det: np.ndarray | None = None) -> np.ndarray:
    """Opacity-aware quad half-axes: (N, 2, 2), rows are the two half-axis vectors in pixels.

    Along each eigenvector the half-length is ``sqrt(2 ln(255 o)) sqrt(lambda)``: beyond it
    ``o exp(-r^2/2) < 1/255`` and the reference skips the splat.  Zero for ``o <= 1/255``.
    ``det``: the accurate determinant (:func:`covariance_2d_det`; default ``a c - b^2``).

    Guard (stress case det_nonpositive): ``lam2 = mid - root`` cancelled to 0 for a long thin
    splat (entries ~3e7, lam2 0.3), a quad without width (max error 0.35); ``lam2 = det / lam1``
    does not cancel.
    """
    a, b, c = cov2d[:, 0, 0], cov2d[:, 0, 1], cov2d[:, 1, 1]
    det = a * c - b * b if det is None else det
    mid = 0.5 * (a + c)
    root = np.sqrt(np.maximum(discriminant(cov2d), 0.0))
    lam1 = mid + root
    with np.errstate(divide="ignore", invalid="ignore"):
        # (det overflowing to +inf gives det / lam1 = inf: lam2 <= lam1 bounds it.)
        lam2 = np.where(lam1 > 0, np.clip(det / np.where(lam1 > 0, lam1, 1.0), 0.0, lam1), 0.0)
    # Eigenvector of lam1: (b, lam1 - a), or (lam1 - c, b); pick the better conditioned one.
    v1 = np.where((np.abs(a - lam1) < np.abs(c - lam1))[:, None],
                  np.stack([lam1 - c, b], -1), np.stack([b, lam1 - a], -1))
    nrm = np.linalg.norm(v1, axis=-1, keepdims=True)
    v1 = np.where(nrm > 0, v1 / np.where(nrm > 0, nrm, 1.0), np.array([1.0, 0.0], cov2d.dtype))
    v2 = np.stack([-v1[:, 1], v1[:, 0]], -1)
    with np.errstate(divide="ignore", invalid="ignore"):
        k = np.sqrt(np.maximum(2.0 * np.log(np.maximum(opacities, 1e-30) / ALPHA_MIN), 0.0))
    return np.stack([v1 * (k * np.sqrt(lam1))[:, None], v2 * (k * np.sqrt(lam2))[:, None]], 1)


def sh_basis(dirs: np.ndarray, degree: int) -> np.ndarray:
    """Real SH basis ``Y_lm(d)`` for unit directions (N, 3) -> (N, K), trig-free form."""
    x, y, z = dirs[:, 0], dirs[:, 1], dirs[:, 2]
    out = [np.full_like(x, SH_C0)]
    if degree >= 1:
        out += [-SH_C1 * y, SH_C1 * z, -SH_C1 * x]
    if degree >= 2:
        xx, yy, zz, xy, yz, xz = x * x, y * y, z * z, x * y, y * z, x * z
        out += [SH_C2[0] * xy, SH_C2[1] * yz, SH_C2[2] * (2 * zz - xx - yy), SH_C2[3] * xz,
                SH_C2[4] * (xx - yy)]
    if degree >= 3:
        out += [SH_C3[0] * y * (3 * xx - yy), SH_C3[1] * xy * z, SH_C3[2] * y * (4 * zz - xx - yy),
                SH_C3[3] * z * (2 * zz - 3 * xx - 3 * yy), SH_C3[4] * x * (4 * zz - xx - yy),
                SH_C3[5] * z * (xx - yy), SH_C3[6] * x * (xx - 3 * yy)]
    return np.stack(out, axis=-1)


def sh_color(sh: np.ndarray, dirs: np.ndarray, degree: int | None = None) -> np.ndarray:
    """Colour ``max(sum h_lm Y_lm(d) + 0.5, 0)``: (N, K, 3) SH, (N, 3) unit dirs -> (N, 3).

    ``degree`` caps the bands used (default: all the data has).
    """
    k_all = sh.shape[1]
    deg = int(round(np.sqrt(k_all))) - 1 if degree is None else min(degree, int(round(np.sqrt(k_all))) - 1)
    k = sh_coeff_count(deg)
    basis = sh_basis(dirs, deg)
    return np.maximum(np.einsum("nk,nkc->nc", basis, sh[:, :k]) + SH_OFFSET, 0.0)


def view_dirs(means: np.ndarray, camera: Camera, scene_rotation: np.ndarray | None = None) -> np.ndarray:
    """Unit directions ``normalize(p_w - camera_centre)`` (N, 3) for SH evaluation.

    With a transform rotation (scene-to-world), the direction is rotated back into the scene's frame.
    """
    d = means - camera.center.astype(means.dtype)
    if scene_rotation is not None:
        d = d @ np.asarray(scene_rotation, means.dtype)  # R^T d, row-vector form
    n = np.linalg.norm(d, axis=-1, keepdims=True)
    return d / np.where(n > 0, n, 1.0)


@dataclass(frozen=True)
class Projected:
    """Per-splat screen quantities (the output of :func:`project`), N rows.

    Attributes:
        p_cam: (N, 3) camera-space centres.  depth: (N,) view z (fisheye and
            equirectangular: distance from the camera, :meth:`~splatgl.cameras.model.CameraModel.depth`).
        mean2d: (N, 2) pixel coordinates.  cov2d: (N, 2, 2) dilated covariance (px^2).
        conic: (N, 3) inverse covariance (a, b, c).  det: (N,) det of cov2d.
        color: (N, 3) SH colour.  opacity: (N,) opacity (times the AA factor when enabled).
    """

    p_cam: np.ndarray
    depth: np.ndarray
    mean2d: np.ndarray
    cov2d: np.ndarray
    conic: np.ndarray
    det: np.ndarray
    color: np.ndarray
    opacity: np.ndarray


def project(means: np.ndarray, rotations: np.ndarray, scales: np.ndarray, opacities: np.ndarray,
            sh: np.ndarray, camera: Camera, antialias: bool = False,
            sh_degree: int | None = None, low_pass: float = LOW_PASS) -> Projected:
    """Project 3DGS splats to the screen (no culling): the twin of the vertex stage's math.

    Arrays as in :class:`splatgl.scene.splats.Scene` (activated), in the dtype wanted for the math.
    ``low_pass``: the dilation in px^2 (the GPU paths' LOW_PASS; the reference's ``low_pass``
    emulation knob changes it, :mod:`splatgl.scene.emulation`).
    """
    p_cam = eye_space(to_camera(means, camera), camera)  # ODS: per-splat eye
    rot = quat_to_rotmat(rotations)
    cov2d = covariance_2d(covariance_3d(rot, scales), p_cam, camera, low_pass)
    con, det = conic(cov2d, covariance_2d_det(cov2d, screen_factor(rot, scales, p_cam, camera),
                                              low_pass))
    opac = opacities * antialias_factor(cov2d, low_pass) if antialias else opacities
    color = sh_color(sh, view_dirs(means, camera), sh_degree)
    return Projected(p_cam, camera.model.depth(p_cam), project_means(p_cam, camera), cov2d,
                     con, det, color, opac)


def splat_reach(max_scale: np.ndarray, opacities: np.ndarray) -> np.ndarray:
    """(N,) world radius within which a splat can reach alpha 1/255: ``k max_scale`` with the
    opacity-aware sigma count ``k = sqrt(2 ln(255 o))`` (at most ~3.33)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        k = np.sqrt(np.maximum(2.0 * np.log(np.maximum(opacities, 1e-30) / ALPHA_MIN), 0.0))
    return (k * max_scale).astype(np.float64)
