"""Float64 checks of the projection math (splatgl/splatmath/project.py) against the formulas themselves."""

from __future__ import annotations

import math

import numpy as np
import pytest

from splatgl.cameras.camera import Camera
from splatgl.cameras.poses import look_at, orbit
from splatgl.constants import LOW_PASS, SH_C0, SH_C1
from splatgl.splatmath.project import (antialias_factor, conic, covariance_2d, covariance_2d_det,
                                       covariance_3d, discriminant, ellipse_axes, jacobian,
                                       project_means, quat_to_rotmat, reference_radius, screen_factor,
                                       sh_basis, sh_color, to_camera)

RNG = np.random.default_rng(7)


def _axis_angle(axis, angle):
    axis = np.asarray(axis, float) / np.linalg.norm(axis)
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + math.sin(angle) * k + (1 - math.cos(angle)) * k @ k  # Rodrigues


def test_quat_to_rotmat_matches_rodrigues_and_ignores_norm():
    axes = RNG.normal(size=(20, 3))
    angles = RNG.uniform(-math.pi, math.pi, 20)
    for axis, angle in zip(axes, angles):
        n = axis / np.linalg.norm(axis)
        q = np.concatenate([[math.cos(angle / 2)], n * math.sin(angle / 2)])
        for scale in (1.0, 1e-3, 37.0):  # unnormalised quaternions describe the same rotation
            r = quat_to_rotmat((q * scale)[None])[0]
            np.testing.assert_allclose(r, _axis_angle(axis, angle), atol=1e-12)


def test_covariance_3d_is_r_s_st_rt():
    q = RNG.normal(size=(10, 4))
    s = RNG.uniform(0.01, 2.0, size=(10, 3))
    r = quat_to_rotmat(q)
    got = covariance_3d(r, s)
    for i in range(10):
        m = r[i] @ np.diag(s[i])
        np.testing.assert_allclose(got[i], m @ m.T, rtol=1e-12, atol=1e-15)
        # eigenvalues are the squared scales
        np.testing.assert_allclose(np.sort(np.linalg.eigvalsh(got[i])), np.sort(s[i] ** 2), rtol=1e-9)


def _camera():
    return Camera(320, 240, 300.0, 280.0, 161.0, 118.5, orbit([0.1, 0.2, 0.3], 4.0, 30.0, 15.0))


def test_covariance_2d_and_conic_against_formula():
    cam = _camera()
    means = RNG.normal(size=(15, 3)) * 0.5 + [0.1, 0.2, 0.3]
    cov3d = covariance_3d(quat_to_rotmat(RNG.normal(size=(15, 4))), RNG.uniform(0.01, 0.3, (15, 3)))
    p = to_camera(means, cam)
    got = covariance_2d(cov3d, p, cam)
    w = cam.rotation
    for i in range(15):
        x, y, z = p[i]
        tx, ty = cam.width / (2 * cam.fx), cam.height / (2 * cam.fy)
        xz = min(max(x / z, -1.3 * tx), 1.3 * tx)
        yz = min(max(y / z, -1.3 * ty), 1.3 * ty)
        j = np.array([[cam.fx / z, 0, -cam.fx * xz / z], [0, cam.fy / z, -cam.fy * yz / z]])
        expect = j @ w @ cov3d[i] @ w.T @ j.T + LOW_PASS * np.eye(2)
        np.testing.assert_allclose(got[i], expect, rtol=1e-12)
    con, det = conic(got)
    for i in range(15):
        inv = np.linalg.inv(got[i])
        np.testing.assert_allclose(con[i], [inv[0, 0], inv[0, 1], inv[1, 1]], rtol=1e-10)
        assert det[i] == pytest.approx(np.linalg.det(got[i]), rel=1e-10)


def test_screen_factor_and_its_determinant():
    """M = J W R S gives Sigma' = M M^T + 0.3 I; det(Sigma') from M's minors (Cauchy-Binet)
    equals the plain determinant, and stays accurate in float32 where a c - b^2 cancels."""
    cam = _camera()
    rot = quat_to_rotmat(RNG.normal(size=(15, 4)))
    scales = RNG.uniform(0.01, 0.3, (15, 3))
    p = to_camera(RNG.normal(size=(15, 3)) * 0.5 + [0.1, 0.2, 0.3], cam)
    m = screen_factor(rot, scales, p, cam)
    cov = covariance_2d(covariance_3d(rot, scales), p, cam)
    np.testing.assert_allclose(m @ np.swapaxes(m, -1, -2) + LOW_PASS * np.eye(2), cov, rtol=1e-12)
    np.testing.assert_allclose(covariance_2d_det(cov, m), np.linalg.det(cov), rtol=1e-9)
    # A needle 1e3 long and 1e-3 thin at 45 degrees in the image plane: float32 a c - b^2
    # loses everything, the minors keep it.
    c, s = math.cos(math.pi / 4), math.sin(math.pi / 4)
    needle = np.array([[[1e3 * c, -1e-3 * s, 0.0], [1e3 * s, 1e-3 * c, 0.0]]])
    want = np.linalg.det(needle[0] @ needle[0].T + LOW_PASS * np.eye(2))
    m32 = needle.astype(np.float32)
    cov32 = m32 @ np.swapaxes(m32, -1, -2) + np.float32(LOW_PASS) * np.eye(2, dtype=np.float32)
    got = covariance_2d_det(cov32, m32)
    assert got.dtype == np.float32 and got[0] == pytest.approx(want, rel=1e-4)


def test_discriminant_is_mid_squared_minus_det_and_never_nan():
    cov = np.array([[[9.0, 2.0], [2.0, 1.0]]])
    assert discriminant(cov)[0] == pytest.approx(25.0 - 5.0, rel=1e-12)
    huge = np.array([[[3e19, 1e19], [1e19, 1e19]]], np.float32)  # mid^2 overflows float32
    got = discriminant(huge)[0]
    assert np.isfinite(got) and got == pytest.approx(1e38 + 1e38, rel=1e-6)


def test_dilation_is_in_true_pixel_units():
    """A tiny isotropic splat's Sigma' is (f s / z)^2 + 0.3 px^2, not the half-pixel 0.075."""
    cam = Camera(100, 100, 200.0, 200.0, 50.0, 50.0)
    s, z = 0.01, 4.0
    cov = covariance_2d(covariance_3d(np.eye(3)[None], np.array([[s, s, s]])),
                        np.array([[0.0, 0.0, z]]), cam)[0]
    assert cov[0, 0] == pytest.approx((200 * s / z) ** 2 + 0.3, rel=1e-12)
    assert cov[0, 1] == pytest.approx(0.0, abs=1e-15)


def test_jacobian_clamp_moves_only_the_jacobian():
    cam = Camera(100, 100, 50.0, 50.0, 50.0, 50.0)  # tan(half fov) = 1
    p = np.array([[10.0, 0.0, 1.0]])  # x/z = 10, far outside 1.3
    j = jacobian(p, cam)[0]
    assert j[0, 2] == pytest.approx(-50.0 * 1.3 / 1.0)
    assert project_means(p, cam)[0, 0] == pytest.approx(50.0 * 10.0 + 50.0)  # mean not moved


def test_orthographic_jacobian_is_constant():
    cam = Camera.orthographic(64, 64, 10.0)
    j = jacobian(np.array([[1.0, 2.0, 3.0], [0.0, 0.0, 50.0]]), cam)
    np.testing.assert_allclose(j[0], [[10, 0, 0], [0, 10, 0]])
    np.testing.assert_allclose(j[1], j[0])


def test_antialias_factor_formula():
    cov = np.array([[[2.0, 0.5], [0.5, 1.5]]])
    und = cov[0] - LOW_PASS * np.eye(2)
    expect = math.sqrt(max(2.5e-5, np.linalg.det(und) / np.linalg.det(cov[0])))
    assert antialias_factor(cov)[0] == pytest.approx(expect, rel=1e-12)


def test_reference_radius_and_ellipse_axes():
    cov = np.array([[[9.0, 0.0], [0.0, 1.0]], [[5.0, 4.0], [4.0, 5.0]]])
    np.testing.assert_array_equal(reference_radius(cov), [9, 9])  # ceil(3 * 3)
    axes = ellipse_axes(cov, np.array([1.0, 1.0]))
    k = math.sqrt(2 * math.log(255.0))
    np.testing.assert_allclose(np.linalg.norm(axes[0], axis=1), [3 * k, k], rtol=1e-12)
    # second covariance: eigenvalues 9 along (1, 1), 1 along (1, -1)
    np.testing.assert_allclose(np.abs(axes[1, 0]) / np.linalg.norm(axes[1, 0]),
                               [1 / math.sqrt(2)] * 2, rtol=1e-12)
    # at the quad's corner the Gaussian has fallen to exactly 1/255
    con, _ = conic(cov)
    d = axes[1, 0]
    power = -0.5 * (con[1, 0] * d[0] ** 2 + 2 * con[1, 1] * d[0] * d[1] + con[1, 2] * d[1] ** 2)
    assert math.exp(power) == pytest.approx(1 / 255, rel=1e-9)


def test_sh_basis_is_orthonormal_on_the_sphere():
    """Monte-Carlo check: the 16 basis functions are orthonormal over the unit sphere."""
    d = np.random.default_rng(3).normal(size=(400_000, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    y = sh_basis(d, 3)
    gram = 4 * math.pi * (y.T @ y) / len(d)
    np.testing.assert_allclose(gram, np.eye(16), atol=0.02)


def test_sh_basis_low_bands_closed_form():
    d = np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    y = sh_basis(d, 1)
    np.testing.assert_allclose(y[:, 0], SH_C0)
    np.testing.assert_allclose(y[0, 1:], [0, SH_C1, 0])      # -C1 y, C1 z, -C1 x
    np.testing.assert_allclose(y[1, 1:], [0, 0, -SH_C1])
    np.testing.assert_allclose(y[2, 1:], [-SH_C1, 0, 0])


def test_sh_color_offset_clamp_and_degree_cap():
    sh = np.zeros((2, 16, 3))
    sh[0, 0] = [-10.0, 0.0, 10.0]
    sh[1, 3] = [1.0, 1.0, 1.0]  # Y_1,1 = -C1 x
    d = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0]])
    c = sh_color(sh, d)
    np.testing.assert_allclose(c[0], [0.0, 0.5, 0.5 + 10 * SH_C0])  # clamped below at 0 only
    np.testing.assert_allclose(c[1], 0.5 + SH_C1)
    np.testing.assert_allclose(sh_color(sh, d, degree=0)[1], 0.5)


def test_look_at_is_a_rigid_opencv_view():
    eye, target = np.array([1.0, -2.0, -3.0]), np.array([0.2, 0.1, 0.4])
    m = look_at(eye, target)
    r = m[:3, :3]
    np.testing.assert_allclose(r @ r.T, np.eye(3), atol=1e-12)
    assert np.linalg.det(r) == pytest.approx(1.0)
    p = to_camera(target[None], Camera(10, 10, 1, 1, 5, 5, m))[0]
    np.testing.assert_allclose(p[:2], 0, atol=1e-12)
    assert p[2] == pytest.approx(np.linalg.norm(target - eye))
    # world -y (the default up) projects upwards in the image: smaller v
    above = to_camera((target + [0, -0.1, 0])[None], Camera(10, 10, 1, 1, 5, 5, m))[0]
    assert above[1] < 0


def test_frustum_camera_equals_intrinsics():
    cam = Camera.from_frustum(200, 100, left=-0.3, right=0.5, top=0.2, bottom=-0.1, near=0.5, far=10)
    assert (cam.fx, cam.fy) == pytest.approx((200 * 0.5 / 0.8, 100 * 0.5 / 0.3))
    # the frustum's corners land on the image corners
    p = np.array([[-0.3, -0.2, 0.5], [0.5, 0.1, 0.5]])  # GL top (+y up) is OpenCV -y
    np.testing.assert_allclose(project_means(p, cam), [[0, 0], [200, 100]], atol=1e-12)
