"""The quad path on the GPU (Mesa llvmpipe through EGL) against analytic images and its NumPy twin.

Tolerances: RGBA32F images match the float64 twin to 2e-5 absolute.  The GPU evaluates the same
formulas in float32; the largest term, exp(power) with |power| up to ~5.5 and the conic's
float32 rounding, gives relative errors ~1e-6, and blending a few layers adds a few ulps.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

import helpers
from helpers import image_tol, save_failure_images
from helpers import scene_with_colors as make_scene
from splatgl.splatmath.blend import blend_front_to_back, splat_alpha
from splatgl.cameras.camera import Camera
from splatgl.cameras.poses import orbit
from splatgl.cameras.view import View, draft_low_pass
from splatgl.constants import ALPHA_MIN, FAST_CORNER_SIGMAS, LOW_PASS
from splatgl.splatmath.project import ellipse_axes, project
from splatgl.renderers.quad import composite
from splatgl.api import default_camera
from splatgl.scene.splats import Scene
from splatgl.scene.settings import Precision, Preprocess, QuadExtent, RenderSettings, resolve_near
from splatgl.order.sort import depth_sort

TOL32 = 2e-5


def twin_image(scene: Scene, camera: Camera, background=(0.0, 0.0, 0.0), antialias: bool = False,
               low_pass: float = LOW_PASS) -> np.ndarray:
    """Float64 NumPy twin of the whole quad path for a small scene: (H, W, 4)."""
    pr = project(scene.means.astype(np.float64), scene.rotations.astype(np.float64),
                 scene.scales.astype(np.float64), scene.opacities.astype(np.float64),
                 scene.sh.astype(np.float64), camera, antialias=antialias, low_pass=low_pass)
    order = depth_sort(pr.depth.astype(np.float32), np.arange(scene.count, dtype=np.uint32))
    alpha = splat_alpha(pr.mean2d[order], pr.conic[order], pr.opacity[order], camera.width, camera.height)
    rgba = blend_front_to_back(alpha, pr.color[order])
    return composite(rgba, background)


def assert_images_close(got, expected, tol, name, artifacts_dir):
    tol = image_tol(tol)
    err = float(np.abs(got - expected).max())
    if not err <= tol:
        note = save_failure_images(artifacts_dir, name, got, expected)
        pytest.fail(f"{name}: max abs error {err:.3g} > {tol:.3g}; {note}")


def test_single_isotropic_gaussian_matches_closed_form(gl_renderer, artifacts_dir):
    cam = Camera(64, 48, 80.0, 80.0, 30.3, 25.7)
    s, z, o = 0.15, 4.0, 0.8
    scene = make_scene([[0.0, 0.0, z]], [[1, 0, 0, 0]], [[s, s, s]], [o], [[0.2, 0.6, 0.9]])
    got = gl_renderer.render(scene, cam)
    u, v = np.meshgrid(np.arange(64) + 0.5, np.arange(48) + 0.5)
    var = (80.0 * s / z) ** 2 + 0.3  # (f s / z)^2 plus the 0.3 px^2 low pass
    alpha = np.minimum(0.99, o * np.exp(-((u - 30.3) ** 2 + (v - 25.7) ** 2) / (2 * var)))
    alpha = np.where(alpha >= 1 / 255, alpha, 0.0)
    expected = np.concatenate([alpha[..., None] * [0.2, 0.6, 0.9], alpha[..., None]], -1)
    assert_images_close(got, expected, TOL32, "single_gaussian", artifacts_dir)
    assert got[..., 3].max() > 0.7  # the splat is really there


@pytest.mark.parametrize("angle_deg", [0.0, 45.0])
def test_thin_ellipse_orientation(gl_renderer, artifacts_dir, angle_deg):
    """The y-flip trap: a thin ellipse rotated about the view axis must keep its orientation."""
    cam = Camera(96, 96, 120.0, 120.0, 48.0, 48.0)
    a = math.radians(angle_deg)
    q = [math.cos(a / 2), 0, 0, math.sin(a / 2)]  # rotation about camera z (into the screen)
    scene = make_scene([[0.0, 0.0, 3.0]], [q], [[0.6, 0.03, 0.03]], [0.9], [[1, 1, 1]])
    got = gl_renderer.render(scene, cam)
    assert_images_close(got, twin_image(scene, cam), TOL32, f"ellipse_{angle_deg:g}", artifacts_dir)
    # Independent check of the direction: the alpha-weighted covariance of the image.
    u, v = np.meshgrid(np.arange(96) + 0.5, np.arange(96) + 0.5)
    w = got[..., 3]
    du, dv = u - (w * u).sum() / w.sum(), v - (w * v).sum() / w.sum()
    cuu, cvv, cuv = (w * du * du).sum(), (w * dv * dv).sum(), (w * du * dv).sum()
    major = 0.5 * math.degrees(math.atan2(2 * cuv, cuu - cvv))
    # +45 degrees about +z (OpenCV: x right, y down) points the major axis right and down.
    assert major == pytest.approx(angle_deg, abs=0.5)


def _random_splats(seed: int, scales: tuple[float, float], n: int = 40) -> Scene:
    """``n`` splats around z = 4 with scales in ``scales`` and opacity at most 0.35."""
    rng = np.random.default_rng(seed)
    means = rng.normal(size=(n, 3)) * [0.6, 0.5, 0.4] + [0, 0, 4]
    return make_scene(means, rng.normal(size=(n, 4)), rng.uniform(*scales, (n, 3)),
                      rng.uniform(0.05, 0.35, n), rng.uniform(0, 1, (n, 3)))


def test_random_scene_matches_twin_in_both_extents(gl_renderer, artifacts_dir):
    # Opacity <= 0.35 keeps every alpha >= 1/255 pixel inside both the ellipse and the
    # 3-sigma square quads, so the two extents must give the same image as the dense twin.
    scene = _random_splats(11, (0.02, 0.25))
    cam = Camera(80, 60, 70.0, 70.0, 40.0, 30.0)
    expected = twin_image(scene, cam)
    for extent in (QuadExtent.ELLIPSE, QuadExtent.SQUARE):
        got = gl_renderer.render(scene, cam, RenderSettings(extent=extent))
        assert_images_close(got, expected, TOL32, f"random_{extent.value}", artifacts_dir)


@pytest.mark.parametrize("antialias, preprocess", [(False, Preprocess.COMPUTE),
                                                    (True, Preprocess.COMPUTE),
                                                    (False, Preprocess.VERTEX)])
def test_a_views_own_low_pass_matches_the_twin(gl_renderer, artifacts_dir, antialias, preprocess):
    """A View's low_pass (a draft's dilation, draft_low_pass) replaces LOW_PASS in the 2D
    covariance, its determinant and the antialiasing factor, in the pre-pass and the draw: the
    image is the twin's with that low pass, and differs from the default one."""
    scene = _random_splats(12, (0.005, 0.1))
    full = Camera(160, 120, 140.0, 140.0, 80.0, 60.0)
    cam = full.resized(80, 60)                         # a draft at scale 0.5
    low_pass = draft_low_pass(full, cam)
    assert low_pass == pytest.approx(LOW_PASS * 0.25) and draft_low_pass(full, full) is None
    settings = RenderSettings(antialias=antialias, preprocess=preprocess)
    quad = gl_renderer.renderer_for(scene, settings)
    view = View.of(cam, settings, scene)
    got = quad.render(dataclasses.replace(view, low_pass=low_pass)).rgba
    expected = twin_image(scene, cam, antialias=antialias, low_pass=low_pass)
    name = f"aa{int(antialias)}_{preprocess.value}"
    assert_images_close(got, expected, TOL32, f"view_low_pass_{name}", artifacts_dir)
    default = quad.render(view).rgba                   # the same renderer, LOW_PASS again
    assert_images_close(default, twin_image(scene, cam, antialias=antialias), TOL32,
                        f"view_default_low_pass_{name}", artifacts_dir)
    assert np.abs(got - default).max() > 0.05          # the small splats really are smaller


def test_fast_extent_is_the_gaussian_cut_at_a_fixed_rectangle(gl_renderer, artifacts_dir):
    """The fast mode's identity conic on whitened corner coordinates is the exact Gaussian,
    truncated to |w1|, |w2| <= 2 sqrt(2) along the ellipse axes."""
    rng = np.random.default_rng(13)
    n = 30
    scene = make_scene(rng.normal(size=(n, 3)) * [0.6, 0.5, 0.4] + [0, 0, 4], rng.normal(size=(n, 4)),
                       rng.uniform(0.03, 0.25, (n, 3)), rng.uniform(0.3, 0.95, n), rng.uniform(0, 1, (n, 3)))
    cam = Camera(80, 60, 70.0, 70.0, 40.0, 30.0)
    pr = project(scene.means.astype(np.float64), scene.rotations.astype(np.float64),
                 scene.scales.astype(np.float64), scene.opacities.astype(np.float64),
                 scene.sh.astype(np.float64), cam)
    order = depth_sort(pr.depth.astype(np.float32), np.arange(n, dtype=np.uint32))
    unit = ellipse_axes(pr.cov2d, np.full(n, ALPHA_MIN * math.exp(0.5)))[order]  # one sigma
    u, v = np.meshgrid(np.arange(80) + 0.5, np.arange(60) + 0.5)
    d = np.stack([u[None] - pr.mean2d[order, 0, None, None], v[None] - pr.mean2d[order, 1, None, None]], -1)
    # whitened coordinates: w_i = (d . axis_i) / |axis_i|^2
    w1 = (d @ unit[:, 0][:, None, :, None])[..., 0] / (unit[:, 0] ** 2).sum(-1)[:, None, None]
    w2 = (d @ unit[:, 1][:, None, :, None])[..., 0] / (unit[:, 1] ** 2).sum(-1)[:, None, None]
    inside = (np.abs(w1) <= FAST_CORNER_SIGMAS) & (np.abs(w2) <= FAST_CORNER_SIGMAS)
    alpha = splat_alpha(pr.mean2d[order], pr.conic[order], pr.opacity[order], 80, 60, inside)
    expected = blend_front_to_back(alpha, pr.color[order])
    got = gl_renderer.render(scene, cam, RenderSettings(extent=QuadExtent.FAST))
    # Pixels on the rectangle's edge may fall either side in float32: compare with a mask
    # that drops pixels within 1e-3 sigma of the edge.
    edge = np.any(np.abs(np.maximum(np.abs(w1), np.abs(w2)) - FAST_CORNER_SIGMAS) < 1e-3, axis=0)
    assert_images_close(np.where(edge[..., None], 0, got), np.where(edge[..., None], 0, expected),
                        TOL32, "fast_extent", artifacts_dir)


def test_depth_order_front_to_back(gl_renderer):
    """Input order back-to-front: the sort must still put the near red splat in front."""
    cam = Camera(32, 32, 40.0, 40.0, 16.0, 16.0)
    scene = make_scene([[0, 0, 6.0], [0, 0, 3.0]], [[1, 0, 0, 0]] * 2, [[0.5] * 3, [0.3] * 3],
                       [0.99, 0.99], [[0, 0, 1], [1, 0, 0]])
    px = gl_renderer.render(scene, cam)[16, 16]
    assert px[0] > 0.9 and px[2] < 0.05


def test_background_compositing(gl_renderer):
    cam = Camera(48, 32, 50.0, 50.0, 24.0, 16.0)
    scene = make_scene([[0.1, 0, 3.0], [-0.2, 0.1, 4.0]], [[1, 0, 0, 0]] * 2,
                       [[0.2] * 3, [0.3, 0.1, 0.2]], [0.7, 0.5], [[1, 0.5, 0], [0, 0.5, 1]])
    bg = (0.25, 0.5, 1.0)
    plain = gl_renderer.render(scene, cam)
    got = gl_renderer.render(scene, cam, RenderSettings(background=bg))
    np.testing.assert_allclose(got[..., :3], plain[..., :3] + (1 - plain[..., 3:]) * bg, atol=1e-6)
    np.testing.assert_allclose(got[0, 0, :3], bg, atol=1e-6)  # empty corner shows the background
    np.testing.assert_array_equal(got[..., 3], plain[..., 3])


def test_precisions_ordered_by_error(gl_renderer):
    """Many translucent layers: RGBA32F beats RGBA16F beats RGBA8 against the float64 twin."""
    rng = np.random.default_rng(5)
    n = 150
    means = np.column_stack([rng.normal(0, 0.05, n), rng.normal(0, 0.05, n), rng.uniform(3, 5, n)])
    scene = make_scene(means, [[1, 0, 0, 0]] * n, np.full((n, 3), 0.4), np.full(n, 0.08),
                       rng.uniform(0, 1, (n, 3)))
    cam = Camera(40, 40, 40.0, 40.0, 20.0, 20.0)
    expected = twin_image(scene, cam)
    errors = {}
    for p in Precision:
        got = gl_renderer.render(scene, cam, RenderSettings(precision=p))
        errors[p] = float(np.abs(got - expected).max())
    assert errors[Precision.RGBA32F] < image_tol(TOL32)
    if not helpers.GPU_GL:  # (a GPU's shader math alone errs by about RGBA16F's rounding)
        assert errors[Precision.RGBA32F] < errors[Precision.RGBA16F] < errors[Precision.RGBA8]
    assert errors[Precision.RGBA8] > 1 / 255  # 8-bit accumulation visibly discolours


def test_behind_camera_and_offscreen_culling(gl_renderer):
    cam = Camera(32, 32, 40.0, 40.0, 16.0, 16.0)
    # Behind the camera: after a perspective divide it would mirror into view.
    behind = make_scene([[0, 0, -3.0]], [[1, 0, 0, 0]], [[0.5] * 3], [0.9], [[1, 1, 1]])
    assert gl_renderer.render(behind, cam)[..., 3].max() == 0.0
    # Centre off-screen to the right, but its extent reaches into the image.
    edge = make_scene([[2.3, 0, 4.0]], [[1, 0, 0, 0]], [[0.3] * 3], [0.9], [[1, 1, 1]])
    got = gl_renderer.render(edge, cam)
    assert got[..., 3].max() > 0.05
    np.testing.assert_allclose(got, twin_image(edge, cam), atol=TOL32)


def test_camera_change_resorts(gl_renderer):
    """Moving the camera to the other side must reverse which splat is in front."""
    scene = make_scene([[0, 0, -0.5], [0, 0, 0.5]], [[1, 0, 0, 0]] * 2, [[0.3] * 3] * 2,
                       [0.99, 0.99], [[1, 0, 0], [0, 0, 1]])
    front = Camera(32, 32, 40.0, 40.0, 16.0, 16.0, orbit([0, 0, 0], 4.0, 180.0, 0.0))
    back = front.with_pose(orbit([0, 0, 0], 4.0, 0.0, 0.0))
    assert gl_renderer.render(scene, front)[16, 16, 0] > 0.9  # red (z = -0.5) nearer
    assert gl_renderer.render(scene, back)[16, 16, 2] > 0.9   # blue nearer from behind


def test_sh_degree_three_colour_matches_twin(gl_renderer, artifacts_dir):
    rng = np.random.default_rng(9)
    n = 25
    sh = rng.normal(0, 0.4, (n, 16, 3))
    scene = Scene.from_activated(rng.normal(size=(n, 3)) * 0.5, rng.normal(size=(n, 4)),
                                 rng.uniform(0.05, 0.2, (n, 3)), rng.uniform(0.1, 0.3, n), sh)
    cam = Camera(64, 64, 60.0, 60.0, 32.0, 32.0, orbit([0, 0, 0], 3.0, 40.0, 25.0))
    got = gl_renderer.render(scene, cam)
    assert_images_close(got, twin_image(scene, cam), TOL32, "sh3", artifacts_dir)
    capped = gl_renderer.render(scene, cam, RenderSettings(sh_degree=0))
    assert_images_close(capped, twin_image(scene.with_sh_degree(0), cam), TOL32, "sh3_cap0", artifacts_dir)


def test_default_camera_keeps_a_small_object(gl_renderer):
    """A 0.2-unit object framed by the default camera is not culled by the near plane."""
    rng = np.random.default_rng(2)
    n = 500
    means = rng.normal(size=(n, 3)) * 0.03
    scene = make_scene(means, [[1, 0, 0, 0]] * n, np.full((n, 3), 0.01), np.full(n, 0.6),
                       rng.uniform(0, 1, (n, 3)))
    cam = default_camera(scene, 64, 48)
    near = resolve_near(RenderSettings(), scene.robust_radius)
    depth = scene.means @ cam.rotation.T + cam.translation
    assert near < depth[:, 2].min()
    assert (gl_renderer.render(scene, cam)[..., 3] > 0.1).mean() > 0.05
    # From closer than the reference's 0.2, the object is still drawn (0.2 would cull it all).
    close = cam.with_pose(orbit(means.mean(0), 0.08, 180.0, 0.0))
    assert (gl_renderer.render(scene, close)[..., 3] > 0.1).mean() > 0.05
    assert gl_renderer.render(scene, close, RenderSettings(near=0.2))[..., 3].max() == 0.0
