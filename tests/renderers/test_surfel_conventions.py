"""2DGS surfels under each convention, against hand-computed float64 cases (issue 17, 16-17).

``Convention.GSPLAT`` follows gsplat's 2DGS rules (``fully_fused_projection_2dgs`` and
``rasterize_to_pixels_2dgs``): the low pass centred on ``means2d``, the centre of the image of
the 1-sigma ellipse; per-axis ``ceil(3.33 sqrt(max(1e-4, e^2)))`` tile radii; depth from the
surfel centre; no per-pixel near test.  ``Convention.INRIA`` keeps the official rasterizer's
low pass on the projected centre and splatgl's depth rule (the hit where the surfel's own
Gaussian wins, the centre's z elsewhere; see :mod:`splatgl.splatmath.surfel`).

The hand case: camera at the origin looking along +z (f = 100 px), a thin surfel in the
horizontal plane y = h, centred at (0, h, z0), tangent axes x (scale s_u) and z (scale s_v),
seen at a grazing angle.  Its 1-sigma ellipse ``(s_u cos t, h, z0 + s_v sin t)`` projects to
``x = f s_u cos t / (z0 + s_v sin t)``, ``y = f h / (z0 + s_v sin t)``: the image spans
``y`` in ``[f h / (z0 + s_v), f h / (z0 - s_v)]``, so its centre is ``f h z0 / (z0^2 - s_v^2)``
(not the projected centre ``f h / z0``) and its half extents are ``f h s_v / (z0^2 - s_v^2)``
in y and ``max cos t / (z0 + s_v sin t) = 1 / sqrt(z0^2 - s_v^2)`` times ``f s_u`` in x.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from splatgl.cameras.camera import Camera
from splatgl.cameras.poses import look_at
from splatgl.constants import ALPHA_MIN, GSPLAT_ALPHA_MAX, ALPHA_MAX
from splatgl.splatmath.project import project_means, quat_to_rotmat, to_camera
from splatgl.reference import Compat, render_reference
from splatgl.scene.splats import Scene, SplatKind
from splatgl.scene.settings import RenderSettings
from splatgl.splatmath.surfel import gsplat_screen, surfel_screen, surfel_transform

F, CX, CY = 100.0, 16.0, 14.0
H_PLANE, Z0 = 0.0625, 2.0          # exact in float32
QUAT = (1.0, 1.0, 0.0, 0.0)        # normalised: 90 degrees about x, tangent axes x and z


def grazing_surfel() -> Scene:
    return Scene.from_activated(np.array([[0.0, H_PLANE, Z0]]), np.array([QUAT]),
                                np.array([[0.01, 1.0]]), np.array([0.9]),
                                np.full((1, 1, 3), 0.5), SplatKind.SURFEL_2D)


# The hand formulas take the values as the scene stores them (float32 log-scales and logits).
S_U, S_V = (float(s) for s in grazing_surfel().scales[0].astype(np.float64))
OPACITY = float(grazing_surfel().opacities[0])
CAMERA = Camera(32, 32, F, F, CX, CY)
SETTINGS = RenderSettings(near=0.01)


def hand_centres():
    projected = np.array([CX, CY + F * H_PLANE / Z0])
    means2d = np.array([CX, CY + F * H_PLANE * Z0 / (Z0 ** 2 - S_V ** 2)])
    extent = np.array([F * S_U / math.sqrt(Z0 ** 2 - S_V ** 2),
                       F * H_PLANE * S_V / (Z0 ** 2 - S_V ** 2)])
    return projected, means2d, extent


def hand_alpha_depth(convention: Compat):
    """(32, 32) alpha and depth D = alpha z of the one surfel, by direct ray-plane geometry."""
    projected, means2d, _ = hand_centres()
    x, y = np.meshgrid(np.arange(32) + 0.5, np.arange(32) + 0.5)
    dy = (y - CY) / F
    with np.errstate(divide="ignore", invalid="ignore"):
        t = H_PLANE / dy                                  # ray (dx, dy, 1) t meets y = h
        u = t * (x - CX) / F / S_U
        v = (t - Z0) / S_V
    gsplat = convention is Compat.GSPLAT
    hit = dy != 0 if gsplat else (dy != 0) & (t > 0)      # gsplat: no near test
    centre = means2d if gsplat else projected
    rho3d = np.where(hit, u * u + v * v, np.inf)
    rho2d = 2.0 * ((x - centre[0]) ** 2 + (y - centre[1]) ** 2)
    amax = GSPLAT_ALPHA_MAX if gsplat else ALPHA_MAX
    alpha = np.minimum(amax, OPACITY * np.exp(-0.5 * np.minimum(rho3d, rho2d)))
    alpha = np.where((alpha >= ALPHA_MIN) & (hit | (not gsplat)), alpha, 0.0)
    z = np.full_like(alpha, Z0) if gsplat else np.where(rho3d <= rho2d, t, Z0)
    return alpha, alpha * z


def test_gsplat_means2d_and_radii_are_the_hand_values():
    projected, means2d, extent = hand_centres()
    assert means2d[1] - projected[1] == pytest.approx(1.0416667, abs=1e-6)  # the blob moves
    ref = render_reference(grazing_surfel(), CAMERA, SETTINGS, np.float64, Compat.GSPLAT)
    np.testing.assert_allclose(ref.projected.mean2d[0], means2d, rtol=1e-12)
    assert ref.projected.radius[0].tolist() == [math.ceil(3.33 * e) for e in extent] == [2, 7]
    # the tile rectangle is gsplat's: floor((m - r) / 16) .. ceil((m + r) / 16) per axis
    assert ref.projected.rect_min[0].tolist() == [0, 0]
    assert ref.projected.rect_max[0].tolist() == [2, 2]
    inria = render_reference(grazing_surfel(), CAMERA, SETTINGS, np.float64, Compat.INRIA)
    np.testing.assert_allclose(inria.projected.mean2d[0], projected, rtol=1e-12)


@pytest.mark.parametrize("convention", [Compat.GSPLAT, Compat.INRIA])
def test_alpha_and_depth_images_are_the_hand_values(convention):
    ref = render_reference(grazing_surfel(), CAMERA, SETTINGS, np.float64, convention)
    alpha, depth = hand_alpha_depth(convention)
    assert (alpha > 0).sum() > 20
    np.testing.assert_allclose(ref.alpha, alpha, rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(ref.depth, depth, rtol=1e-10, atol=1e-12)


def test_the_conventions_differ_where_the_low_pass_centre_moves():
    """The hand images of the two conventions differ by far more than any tolerance: the
    test above could not pass with the low pass on the wrong centre."""
    a_gs, _ = hand_alpha_depth(Compat.GSPLAT)
    a_in, _ = hand_alpha_depth(Compat.INRIA)
    assert np.abs(a_gs - a_in).max() > 0.1


def test_inria_depth_rule_against_a_hand_computed_hit():
    """INRIA: a pixel whose ray meets the surfel's own Gaussian (u^2 + v^2 <= F |d|^2) takes
    the hit's view z; a pixel lit by the low pass alone the centre's z."""
    _, depth = hand_alpha_depth(Compat.INRIA)
    alpha, _ = hand_alpha_depth(Compat.INRIA)
    z = np.divide(depth, alpha, out=np.zeros_like(depth), where=alpha > 0)
    ref = render_reference(grazing_surfel(), CAMERA, SETTINGS, np.float64, Compat.INRIA)
    lit = alpha > 0
    hits = lit & (np.abs(z - Z0) > 1e-6)
    assert hits.sum() >= 4 and (lit & ~hits).sum() >= 4      # both rules are exercised
    # pixel (row 18, column 16): ray (0.005, 0.045, 1) meets y = 0.0625 at t = 1.3889, at
    # u = t 0.005 / s_u = 0.69, v = (t - 2) / s_v = -0.61: rho_3d = 0.86 < F |d|^2 = 4.28
    t = H_PLANE / ((18.5 - CY) / F)
    assert t == pytest.approx(1.3888889, rel=1e-7)
    assert z[18, 16] == pytest.approx(t, rel=1e-12)
    assert ref.depth[18, 16] / ref.alpha[18, 16] == pytest.approx(t, rel=1e-10)
    # pixel (row 17, column 16), next to the projected centre (16, 17.125): the low pass wins
    # (rho_2d = 2 (0.5^2 + 0.375^2) = 0.78 against rho_3d = 0.84), so it takes the centre's z
    assert ref.depth[17, 16] / ref.alpha[17, 16] == pytest.approx(Z0, rel=1e-10)


@pytest.mark.parametrize("seed", [0, 1])
def test_gsplat_screen_matches_gsplat_formulas_and_the_ellipse_box(seed):
    """On random surfels: ``means2d`` and extents equal gsplat's expressions in the uncentred
    ``M = (K W H)^T`` (t = (1, 1, -1), d = t . M_2^2, ...), and equal the centre and half size
    of the box of the projected 1-sigma ellipse sampled at 20,000 angles."""
    rng = np.random.default_rng(seed)
    n = 12
    means = rng.normal(size=(n, 3)) * 0.5 + [0.0, 0.0, 4.0]
    quats = rng.normal(size=(n, 4))
    quats /= np.linalg.norm(quats, axis=1, keepdims=True)
    scales = rng.uniform(0.05, 0.6, (n, 2))
    cam = Camera(96, 72, 80.0, 75.0, 47.3, 35.9, look_at([0.3, -0.2, -0.5], [0.0, 0.0, 4.0]))
    gs = gsplat_screen(surfel_screen(means, quats, scales, cam))
    t = surfel_transform(means, quats, scales, cam)             # rows T_0, T_1, T_2
    sign = np.array([1.0, 1.0, -1.0])
    d = (sign * t[:, 2] ** 2).sum(-1)
    m2d = np.stack([(sign * t[:, r] * t[:, 2]).sum(-1) / d for r in range(2)], -1)
    ext = np.sqrt(np.maximum(1e-4, m2d ** 2 - np.stack(
        [(sign * t[:, r] ** 2).sum(-1) / d for r in range(2)], -1)))
    assert gs.ok.all()
    np.testing.assert_allclose(gs.means2d, m2d, rtol=1e-9)
    np.testing.assert_allclose(gs.extent, ext, rtol=1e-7)
    theta = np.linspace(0.0, 2.0 * math.pi, 20000)
    rot = quat_to_rotmat(quats)
    for i in range(n):
        pts = (means[i] + np.outer(np.cos(theta) * scales[i, 0], rot[i, :, 0])
               + np.outer(np.sin(theta) * scales[i, 1], rot[i, :, 1]))
        px = project_means(to_camera(pts, cam), cam)
        lo, hi = px.min(0), px.max(0)
        np.testing.assert_allclose(gs.means2d[i], (lo + hi) / 2, atol=1e-3)
        np.testing.assert_allclose(gs.extent[i], (hi - lo) / 2, atol=1e-3)
    # rows re-centred on means2d still map (u, v, 1) to pixels minus means2d
    uv1 = np.stack([rng.normal(size=n), rng.normal(size=n), np.ones(n)], -1)
    hom = np.einsum("nij,nj->ni", t, uv1)
    moved = np.einsum("nij,nj->ni", gs.rows, uv1)
    np.testing.assert_allclose(moved[:, :2] / moved[:, 2:], hom[:, :2] / hom[:, 2:] - gs.means2d,
                               atol=1e-9)
