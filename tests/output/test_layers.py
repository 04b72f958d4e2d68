"""Output layers beyond colour (splatgl/output/layers.py): the normal twin against closed forms,
the reference's median depth, count and top contributor against its own pixel listings, and
the quad and tile renderers against the reference on every camera model.

Tolerances (measured on these scenes, docs/layers.md has the real-scene figures):
* tile renderer: the reference's loop in GLSL; accumulated normals within 1e-5 (5e-5 under a
  fisheye, where its colour differs by 1e-5 too: the lens math in float32), the ordered
  layers equal but at a few pixels where float32 rounding of exp moves an alpha across 1/255
  or a running T across 0.5 or 1e-4 (none seen here);
* quad path: normals blend with the colour's weights and share its differences from the
  reference (no early stop, the tile rectangle, DESIGN.md 2): accumulated N within 0.07; the
  ordered pass replays the reference's loop on the reference's tile rectangles, so median
  depth, count and top id differ only where float32 rounding moves a radius across an integer
  or an alpha across 1/255: under 0.2% of pixels for a pinhole view, at most 1% under a lens.
"""

from __future__ import annotations

import numpy as np
import pytest

from helpers import IN_DEPTH, needs_framebuffer_fetch, SURFELS, SURFELS_POSE, random_scene, scene_with_colors
from splatgl.api import default_camera, render_reference_layers
from splatgl.cameras.camera import Camera
from splatgl.cameras.registry import retarget
from splatgl.errors import SplatglError
from splatgl.scene.settings import RendererKind, RenderSettings
from splatgl.output.layers import (BASE, Layer, NormalSpace, concat_outputs, parse_layer_names,
                                   unit_normals, with_layers)
from splatgl.reference.pixel import pixel_splats
from splatgl.renderers.quad_layers import check_ordered
from splatgl.splatmath.normals import splat_normals

ALL = with_layers(*Layer)
#: The quad path's accumulated normals against the reference: unit vectors with the colour's
#: weights, so within the alpha the quad adds beyond the reference (docs/results/summary.md: up to 0.066 at a
#: pixel from the tile rectangle, under 0.01 from the early stop).
QUAD_NORMAL = 0.07


def _flat(rotation=None):
    """One flat splat (scales 1, 0.5, 0.01) turned by a quaternion (w, x, y, z)."""
    return np.array([[1.0, 0.5, 0.01]]), np.array([rotation or [1.0, 0.0, 0.0, 0.0]])


def test_normal_is_the_thin_axis_turned_towards_the_camera():
    scales, q = _flat()
    # Camera-space centre in front (z > 0): the thin axis is z, turned to face the camera (-z).
    n = splat_normals(q, scales, np.array([[0.0, 0.0, 5.0]]), np.eye(3), False, False)
    np.testing.assert_allclose(n, [[0.0, 0.0, -1.0]])
    # Behind the camera plane (a fisheye or panorama sees it): towards the camera is +z.
    n = splat_normals(q, scales, np.array([[0.0, 0.0, -5.0]]), np.eye(3), False, False)
    np.testing.assert_allclose(n, [[0.0, 0.0, 1.0]])
    # 90 degrees about x: the thin axis becomes -y or +y; seen from a centre at +y it is -y.
    c = np.sqrt(0.5)
    n = splat_normals(np.array([[c, c, 0.0, 0.0]]), scales, np.array([[0.0, 3.0, 1.0]]),
                      np.eye(3), False, False)
    np.testing.assert_allclose(n, [[0.0, -1.0, 0.0]], atol=1e-12)
    # Orthographic: every ray is +z, so a normal with n.z > 0 flips whatever the centre.
    tilted = np.array([[np.cos(0.3), 0.0, np.sin(0.3), 0.0]])      # about y
    n = splat_normals(tilted, scales, np.array([[-9.0, 0.0, 5.0]]), np.eye(3), True, False)
    assert n[0, 2] < 0


def test_equal_scales_take_the_first_axis_and_surfels_their_own():
    q = np.array([[1.0, 0.0, 0.0, 0.0]])
    p = np.array([[0.0, 0.0, 4.0]])
    n = splat_normals(q, np.array([[0.2, 0.2, 0.2]]), p, np.eye(3), False, False)
    np.testing.assert_allclose(np.abs(n), [[1.0, 0.0, 0.0]])     # argmin's first: x
    n = splat_normals(q, np.array([[0.01, 0.5]]), p, np.eye(3), False, True)
    np.testing.assert_allclose(n, [[0.0, 0.0, -1.0]])            # a surfel: R[:, 2]


def test_scaled_view_rotation_still_gives_unit_normals():
    scales, q = _flat()
    n = splat_normals(q, scales, np.array([[0.0, 0.0, 5.0]]), 3.0 * np.eye(3), False, False)
    np.testing.assert_allclose(np.linalg.norm(n, axis=1), 1.0)


def test_unit_normals_world_space_and_masking():
    normal = np.array([[[0.0, 0.0, -0.5], [0.0, 0.0, 0.0]]], np.float32)
    alpha = np.array([[0.5, 0.0]], np.float32)
    np.testing.assert_allclose(unit_normals(normal, alpha), [[[0, 0, -1], [0, 0, 0]]])
    pose = np.eye(4)
    pose[:3, :3] = [[0, 0, 1], [0, 1, 0], [-1, 0, 0]]   # camera z = world -x
    world = unit_normals(normal, alpha, pose)
    np.testing.assert_allclose(world[0, 0], [1.0, 0.0, 0.0], atol=1e-7)


def test_layer_names_parse_and_refuse_in_one_line():
    assert parse_layer_names("depth, normal,depth") == (Layer.DEPTH, Layer.NORMAL)
    with pytest.raises(SplatglError, match="unknown layer 'nromal'"):
        parse_layer_names("nromal")
    with pytest.raises(SplatglError, match="empty name"):
        parse_layer_names("depth,,count")


def test_stereo_joins_every_layer():
    scene = random_scene(60, seed=5, **IN_DEPTH)
    out = render_reference_layers(scene, Camera(24, 16, 20.0, 20.0, 12.0, 8.0), RenderSettings(),
                                  layers=ALL)
    both = concat_outputs(out, out, axis=1)
    assert both.normal.shape == (16, 48, 3) and both.top_id.shape == (16, 48)
    assert both.layers == out.layers


def _listing_layers(scene, camera, x, y):
    """Median depth, count and top id of one pixel from its listing (its own blend loop)."""
    listing = pixel_splats(scene, camera, x, y)
    splats = listing.splats
    t_before = [1.0] + [s.transmittance for s in splats[:-1]]
    median = [s.depth for s, t in zip(splats, t_before) if t > 0.5]
    top = max(range(len(splats)), key=lambda k: (splats[k].weight, -k), default=None)
    return (median[-1] if median else 0.0, len(splats),
            splats[top].index if top is not None else -1, listing.alpha)


@pytest.mark.parametrize("surfels", [False, True])
def test_reference_ordered_layers_match_the_pixel_listings(surfels):
    """Every pixel of a small view: the rasterizer's vectorised layers (BatchLayers.add) equal
    what the listing's front-to-back loop says (2DGS's median rule, the first largest weight,
    the count)."""
    if surfels:
        scene = random_scene(300, seed=3, **SURFELS)
        camera = Camera.from_fov(24, 16, 30.0, SURFELS_POSE)
    else:
        scene = random_scene(300, seed=3, **IN_DEPTH)
        camera = Camera(24, 16, 22.0, 22.0, 12.0, 8.0)
    out = render_reference_layers(scene, camera, RenderSettings(), layers=ALL)
    assert (out.count > 3).mean() > 0.3
    for y in range(camera.height):
        for x in range(camera.width):
            median, count, top, alpha = _listing_layers(scene, camera, x, y)
            assert out.count[y, x] == count
            assert out.top_id[y, x] == top
            assert out.median_depth[y, x] == pytest.approx(median, rel=1e-6)
            assert out.alpha[y, x] == pytest.approx(alpha, abs=1e-6)


def test_median_depth_of_two_planes_closed_form():
    """Two wide splats at z 4 and 6: the median is the front one's z where its alpha reaches
    0.5, else the back one's; the count 2 and the top id the heavier weight."""
    means = [[0.0, 0.0, 4.0], [0.0, 0.0, 6.0]]
    quats = [[1.0, 0, 0, 0]] * 2
    scales = [[0.5, 0.5, 0.1], [5.0, 5.0, 0.5]]
    scene = scene_with_colors(means, quats, scales, [0.9, 0.9], [[1, 0, 0], [0, 0, 1]])
    camera = Camera(41, 41, 40.0, 40.0, 20.5, 20.5)
    out = render_reference_layers(scene, camera, RenderSettings(), layers=ALL)
    front = pixel_splats(scene, camera, 20, 20).splats[0]
    assert front.index == 0 and front.alpha > 0.5
    assert out.median_depth[20, 20] == pytest.approx(4.0, rel=1e-6)
    assert out.count[20, 20] == 2 and out.top_id[20, 20] == 0
    corner = pixel_splats(scene, camera, 0, 0).splats
    assert [s.index for s in corner] == [1]
    assert out.median_depth[0, 0] == pytest.approx(6.0, rel=1e-6) and out.top_id[0, 0] == 1
    n = out.unit_normals()
    np.testing.assert_allclose(n[20, 20], [0.0, 0.0, -1.0], atol=1e-6)


def _cameras(scene):
    base = default_camera(scene, 64, 48)
    return {"perspective": base,
            "orthographic": retarget(base, "orthographic"),
            "fisheye": retarget(base, "fisheye", 180.0),
            "equirect": retarget(base.resized(64, 32), "equirectangular")}


def _compare(got, ref, normal_atol, ordered_share):
    np.testing.assert_allclose(got.normal, ref.normal, atol=normal_atol)
    for name in ("median_depth", "count", "top_id"):
        differ = (getattr(got, name) != getattr(ref, name)) & ~np.isclose(
            getattr(got, name), getattr(ref, name), rtol=1e-5, atol=0)
        assert differ.mean() <= ordered_share, (name, differ.mean())
    if not ordered_share:
        np.testing.assert_array_equal(got.count, ref.count)


@pytest.mark.parametrize("model", ["perspective", "orthographic", "fisheye", "equirect"])
def test_quad_and_tile_layers_match_the_reference(gl_renderer, model):
    needs_framebuffer_fetch(gl_renderer.ctx)
    scene = random_scene(600, seed=8, spread=1.0, log_scale=(-3.0, 0.5), logit=(0.5, 1.5))
    camera = _cameras(scene)[model]
    ref = render_reference_layers(scene, camera, RenderSettings(), layers=ALL)
    assert (ref.count > 0).mean() > 0.02
    quad = gl_renderer.render_layers(scene, camera, RenderSettings(), RendererKind.QUAD, layers=ALL)
    _compare(quad, ref, QUAD_NORMAL, 0.01)
    # The colour of a frame with every layer is the plain frame's, bit for bit.
    np.testing.assert_array_equal(quad.rgba, gl_renderer.render(scene, camera, RenderSettings()))
    if model != "equirect":   # the tile renderer draws no panoramas
        tile = gl_renderer.render_layers(scene, camera, RenderSettings(), RendererKind.TILE, layers=ALL)
        _compare(tile, ref, 5e-5, 0.0)   # its colour is 1e-5 off under a fisheye too


@pytest.mark.parametrize("preprocess", ["vertex", "compute"])
def test_quad_layers_with_either_preprocess_and_early_stop(gl_renderer, preprocess):
    needs_framebuffer_fetch(gl_renderer.ctx)
    scene = random_scene(600, seed=9, spread=1.0, log_scale=(-2.5, 0.5), logit=(1.0, 1.5))
    camera = default_camera(scene, 64, 48)
    ref = render_reference_layers(scene, camera, RenderSettings(), layers=ALL)
    for early in ("off", "on"):
        settings = RenderSettings(preprocess=preprocess, early_stop=early)
        quad = gl_renderer.render_layers(scene, camera, settings, layers=ALL)
        _compare(quad, ref, QUAD_NORMAL, 0.01)


def test_surfel_layers_quad_and_tile(gl_renderer):
    needs_framebuffer_fetch(gl_renderer.ctx)
    scene = random_scene(400, seed=4, **SURFELS)
    camera = Camera.from_fov(64, 48, 50.0, SURFELS_POSE)
    ref = render_reference_layers(scene, camera, RenderSettings(), layers=ALL)
    quad = gl_renderer.render_layers(scene, camera, RenderSettings(), layers=ALL)
    tile = gl_renderer.render_layers(scene, camera, RenderSettings(), RendererKind.TILE, layers=ALL)
    _compare(quad, ref, QUAD_NORMAL, 0.01)
    _compare(tile, ref, 1e-5, 0.0)


def test_layers_not_asked_for_are_absent(gl_renderer):
    scene = random_scene(50, seed=1, **IN_DEPTH)
    camera = Camera(32, 24, 30.0, 30.0, 16.0, 12.0)
    for kind in (RendererKind.QUAD, RendererKind.TILE):
        out = gl_renderer.render_layers(scene, camera, RenderSettings(), kind, layers=BASE)
        assert out.normal is None and out.count is None and out.top_id is None


def test_quad_ordered_layers_refused_without_framebuffer_fetch():
    class NoFetch:
        extensions = {"GL_ARB_shader_image_load_store"}
        info = {"GL_RENDERER": "some driver"}

    with pytest.raises(SplatglError, match="median-depth, top-id layers need the OpenGL extension "
                                           "GL_EXT_shader_framebuffer_fetch, which some driver lacks"):
        check_ordered(NoFetch(), with_layers(Layer.TOP_ID, Layer.MEDIAN_DEPTH, Layer.NORMAL))
    check_ordered(NoFetch(), with_layers(Layer.NORMAL, Layer.DEPTH))   # blended layers: fine


def test_normal_space_values():
    assert [m.value for m in NormalSpace] == ["camera", "world"]


def test_ordered_pass_keeps_to_the_reference_tile_rectangle(gl_renderer):
    """The ordered pass drops fragments outside the reference's tile rectangle (3DGS getRect,
    reference/stages.py inria_rect, shaders/lib/tile_rect.glsl), so a pinhole view's counts
    equal the reference's although the quad draws faint fragments beyond it."""
    needs_framebuffer_fetch(gl_renderer.ctx)
    from splatgl.reference.stages import inria_rect

    lo, hi = inria_rect(np.array([[100.5, 40.5]], np.float32), np.array([20]), (10, 10))
    assert lo.tolist() == [[5, 1]] and hi.tolist() == [[8, 4]]     # trunc((p -+ r (+15)) / 16)
    scene = random_scene(600, seed=8, spread=1.0, log_scale=(-3.0, 0.5), logit=(0.5, 1.5))
    camera = default_camera(scene, 64, 48)
    ref = render_reference_layers(scene, camera, RenderSettings(), layers=ALL)
    quad = gl_renderer.render_layers(scene, camera, RenderSettings(), layers=ALL)
    assert (quad.count != ref.count).mean() < 0.002
    np.testing.assert_array_equal(quad.top_id, ref.top_id)
