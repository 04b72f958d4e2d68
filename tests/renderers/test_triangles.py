"""One triangle per splat (QuadRenderer.use_triangles, the viewer's drafts) against the quad.

The triangle circumscribes the ellipse the quad inscribes (the ellipse extent: out to where
alpha falls to 1/255), so every pixel the quad shades is shaded by the triangle with the same
conic and colour.  The images differ only where a pixel centre lies within rounding of the
quad's edge at a tangent point: the quad drops it, the triangle (which reaches further there)
keeps it, a difference of at most 1/255 of alpha per splat at a handful of pixels (measured on
the shared scenes: 108-130 dB).  The square and fast extents shade the quad's corners beyond the
ellipse, which the triangle would cut off: they keep the quad.
"""

from __future__ import annotations

import numpy as np
import pytest

from helpers import random_scene, view_for
from splatgl.api import default_camera
from splatgl.interactive.budget import Level
from splatgl.interactive.draft import LevelRenderer
from splatgl.scene.settings import EarlyStop, QuadExtent, RenderSettings

TRIANGLE = ("TRIANGLE_PER_SPLAT", 1)


def _both(gl_renderer, settings, scene):
    quad = gl_renderer.renderer_for(scene, settings)
    camera = default_camera(scene, 160, 120)
    view = view_for(quad, camera)
    try:
        plain = quad.render(view).rgba
        assert TRIANGLE not in quad.last_frame.extra
        quad.use_triangles(True)
        tri = quad.render(view).rgba
        drew_triangles = TRIANGLE in quad.last_frame.extra
    finally:
        quad.use_triangles(False)
    return quad, plain, tri, drew_triangles


#: At most one splat's 1/255 of alpha (with a few float32 ulps) at a pixel ...
EDGE = 1.0 / 255.0 + 1e-5
#: ... and at no more than this share of the pixels.
EDGE_SHARE = 1e-3


def assert_quad_image(tri, plain):
    diff = np.abs(tri - plain).max(axis=-1)
    assert diff.max() <= EDGE
    assert np.count_nonzero(diff > 1e-5) <= EDGE_SHARE * diff.size


@pytest.mark.parametrize("seed", [3, 7])
def test_triangle_image_equals_the_quad_image(gl_renderer, seed):
    scene = random_scene(400, seed=seed, degree=1)
    _, plain, tri, drew = _both(gl_renderer, RenderSettings(early_stop=False), scene)
    assert drew
    assert plain[..., 3].max() > 0.5          # something drawn
    assert_quad_image(tri, plain)


def test_triangles_never_batch_by_early_termination(gl_renderer):
    scene = random_scene(400, seed=4)
    quad, plain, tri, drew = _both(gl_renderer, RenderSettings(early_stop=EarlyStop.ON), scene)
    assert drew and not quad.batches.batched
    assert_quad_image(tri, plain)


@pytest.mark.parametrize("extent", [QuadExtent.SQUARE, QuadExtent.FAST])
def test_square_and_fast_extents_keep_the_quad(gl_renderer, extent):
    scene = random_scene(200, seed=5)
    quad, plain, tri, drew = _both(gl_renderer, RenderSettings(extent=extent), scene)
    assert not drew
    np.testing.assert_array_equal(tri, plain)


def test_drafts_draw_triangles_and_the_exact_level_quads(gl_renderer):
    scene = random_scene(400, seed=6)
    settings = RenderSettings()
    drafts = LevelRenderer(gl_renderer, scene, settings)
    quad = gl_renderer.renderer_for(scene, settings)
    camera = default_camera(scene, 160, 120)
    try:
        drafts.draw(camera, Level(0.5, None, 0))
        assert TRIANGLE in drafts.renderer.renderer_for(
            scene, RenderSettings(sh_degree=0)).last_frame.extra
        exact = drafts.draw(camera, Level())
        assert TRIANGLE not in quad.last_frame.extra and not quad.gpu.triangles
        np.testing.assert_array_equal(drafts.read(exact), gl_renderer.render(scene, camera, settings))
    finally:
        drafts.release()
