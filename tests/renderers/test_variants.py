"""Quad-path variants give the general path's image (or differ exactly as they should)."""

from __future__ import annotations

import numpy as np
import pytest

from helpers import draw
from splatgl.cameras.poses import orbit
from splatgl.api import default_camera
from splatgl.scene.splats import Scene
from splatgl.scene.settings import Precision, Preprocess, QuadExtent, RenderSettings
from splatgl.order.sort import bucket_sort, depth_sort


def _scene(n=2000, seed=21, degree=3):
    rng = np.random.default_rng(seed)
    k = (degree + 1) ** 2
    return Scene(rng.normal(size=(n, 3)), rng.normal(size=(n, 4)), rng.normal(-3.0, 0.5, (n, 3)),
                 rng.normal(0.5, 1.5, n), rng.normal(0, 0.3, (n, k, 3)))


@pytest.mark.parametrize("extent", list(QuadExtent))
@pytest.mark.parametrize("antialias", [False, True])
def test_compute_prepass_equals_vertex_path(gl_renderer, extent, antialias):
    scene = _scene()
    cam = default_camera(scene, 96, 72)
    a = gl_renderer.render(scene, cam, RenderSettings(extent=extent, antialias=antialias))
    b = gl_renderer.render(scene, cam, RenderSettings(extent=extent, antialias=antialias,
                                                      preprocess=Preprocess.COMPUTE))
    # Same float32 math in a different stage: llvmpipe may fuse differently (few ulps).
    np.testing.assert_allclose(a, b, atol=2e-6)
    assert a[..., 3].max() > 0.5


def test_cull_off_draws_the_same_image(gl_renderer):
    scene = _scene()
    cam = default_camera(scene, 96, 72, distance_scale=0.4)  # many splats off-screen
    on = gl_renderer.renderer_for(scene, RenderSettings())
    off = gl_renderer.renderer_for(scene, RenderSettings(cull=False))
    a, b = draw(on, cam).rgba, draw(off, cam).rgba
    np.testing.assert_array_equal(a, b)
    assert on.last_times.drawn < off.last_times.drawn  # culling really removed splats


def test_sh_degree_variants_equal_padding():
    """An SH0 scene and the same scene padded to SH3 with zeros render identically."""
    from splatgl.api import Renderer

    scene = _scene(degree=0)
    padded = scene.with_sh_degree(3)
    assert padded.sh.shape[1] == 16
    cam = default_camera(scene, 64, 48)
    with Renderer() as r:
        np.testing.assert_allclose(r.render(scene, cam), r.render(padded, cam), atol=1e-6)


def test_bucket16_sort_orders_like_exact_when_depths_are_spread():
    rng = np.random.default_rng(0)
    z = rng.uniform(1.0, 2.0, 5000).astype(np.float32)
    idx = np.arange(5000, dtype=np.uint32)
    exact, buck = depth_sort(z, idx), bucket_sort(z, idx)
    assert np.all(np.diff(z[buck]) >= -(1.0 / 65535) * 1.0001)  # ordered to within one bucket
    # A single far splat coarsens the buckets: near splats then tie and keep index order.
    z2 = np.concatenate([z, np.float32([1e6])])
    idx2 = np.arange(len(z2), dtype=np.uint32)
    assert not np.array_equal(bucket_sort(z2, idx2)[:-1], depth_sort(z2, idx2)[:-1])
    assert np.array_equal(exact, depth_sort(z, idx))


def test_resort_interval_lags_then_catches_up(gl_renderer):
    scene = Scene.from_activated(np.array([[0, 0, -0.5], [0, 0, 0.5]]), np.tile([1.0, 0, 0, 0], (2, 1)),
                                 np.full((2, 3), 0.3), np.array([0.99, 0.99]),
                                 np.array([[[1.5, -1.7, -1.7]], [[-1.7, -1.7, 1.5]]]))  # red, blue
    from splatgl.cameras.camera import Camera

    front = Camera(32, 32, 40.0, 40.0, 16.0, 16.0, orbit([0, 0, 0], 4.0, 180.0, 0.0))
    back = front.with_pose(orbit([0, 0, 0], 4.0, 0.0, 0.0))
    nearly = front.with_pose(orbit([0, 0, 0], 4.0, 0.5, 0.0))
    lazy = gl_renderer.renderer_for(scene, RenderSettings(resort_interval=3))
    assert draw(lazy, front).rgba[16, 16, 0] > 0.8   # sorted: red in front
    assert draw(lazy, back).rgba[16, 16, 0] > 0.8    # stale order: red still drawn first (wrong)
    assert draw(lazy, nearly).rgba[16, 16, 0] > 0.8  # still stale
    assert draw(lazy, back).rgba[16, 16, 2] > 0.8    # third change re-sorts: blue in front


@pytest.mark.parametrize("precision", list(Precision))
def test_prepass_with_depth_and_every_precision(gl_renderer, precision):
    scene = _scene(500)
    cam = default_camera(scene, 64, 48)
    a = gl_renderer.render_layers(scene, cam, RenderSettings(precision=precision))
    b = gl_renderer.render_layers(scene, cam, RenderSettings(precision=precision, preprocess="compute"))
    np.testing.assert_allclose(a.rgba, b.rgba, atol=2e-6 if precision is Precision.RGBA32F else 2e-3)
    np.testing.assert_allclose(a.depth, b.depth, rtol=1e-5, atol=1e-5)


@pytest.mark.parametrize("degree", [1, 3])
def test_half_float_sh_storage_error_is_bounded(gl_renderer, degree):
    """float16 keeps 11 significant bits: each coefficient errs by at most |h| 2^-11.  With
    |Y_lm| < 1.1 over at most 15 bands, a colour errs by at most 15 * 1.1 * max|h| * 2^-11
    (measured about 2e-4, far inside)."""
    scene = _scene(degree=degree)
    cam = default_camera(scene, 96, 72)
    full = gl_renderer.render(scene, cam)
    half = gl_renderer.render(scene, cam, RenderSettings(gpu_storage="half-sh"))
    bound = 15 * 1.1 * float(np.abs(scene.sh[:, 1:]).max()) * 2.0 ** -11
    diff = float(np.abs(full - half).max())
    assert 0 < diff < bound  # not identical (the storage really changed), and bounded
