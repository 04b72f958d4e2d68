"""The per-tile compute renderer (splatgl.renderers.tile) against the NumPy per-tile reference.

Integer stages (tiles touched, tile rectangles, emitted and sorted keys, splat order, tile
ranges) must be identical.  Images: float32 GPU against the float32 reference, 1e-5 absolute.
Both evaluate the same formulas in float32; what differs is operation order (matrix products,
the reference's per-chunk matmul accumulation of C and D) and llvmpipe's exp(), each ~1e-7
relative, so a pixel accumulates a few ulps (measured worst case 1.0e-6).  A pixel whose splat
sits exactly on the 1/255 or 1e-4 thresholds could differ by up to ~0.01; with the seeded scenes
below none does.  Depth (world units, up to ~8) is compared with 1e-5 relative to its maximum.
"""

from __future__ import annotations

import numpy as np
import pytest

from helpers import (IN_DEPTH, SURFELS, SURFELS_POSE, assert_stages_match_reference, random_scene,
                     save_failure_images, shared_file, tile_and_reference)
from splatgl.cameras.camera import Camera
from splatgl.cameras.poses import orbit
from splatgl.formats import load_scene
from splatgl.reference import emit_keys, render_reference, sort
from helpers import draw, image_tol, project, view_for
from splatgl.api import Renderer, default_camera
from splatgl.scene.splats import Scene
from splatgl.scene.settings import RendererKind, RenderSettings
from splatgl.renderers import tile as tile_mod
from splatgl.renderers.tile import KeyLayout, TileRenderer

TOL = 1e-5
DEPTH_TOL_REL = 1e-5


CAM = Camera.from_fov(128, 96, 60.0)


def render_pair(ctx, scene, camera, settings):
    return tile_and_reference(ctx, scene, camera, settings)


def assert_close(got, expected, tol, name, artifacts_dir):
    tol = image_tol(tol)
    err = float(np.abs(got - expected).max()) if got.size else 0.0
    if not err <= tol:
        note = save_failure_images(artifacts_dir, name, got, expected)
        pytest.fail(f"{name}: max abs error {err:.3g} > {tol:.3g}; {note}")


# ------------------------------------------------------------------------------ CPU-only
def test_key_layout_round_trip():
    rng = np.random.default_rng(1)
    n, tiles = 3000, 48
    layout = KeyLayout.choose(n, tiles)
    assert layout.packed and layout.depth_shift == 12 and layout.tile_shift == 43
    tile = rng.integers(0, tiles, 500).astype(np.uint64)
    depth = rng.uniform(0.01, 100.0, 500).astype(np.float32).view(np.uint32).astype(np.uint64)
    index = rng.integers(0, n, 500).astype(np.uint64)
    packed = (tile << np.uint64(43)) | (depth << np.uint64(12)) | index
    ref_keys, values = layout.to_reference(packed)
    np.testing.assert_array_equal(ref_keys, (tile << np.uint64(32)) | depth)
    np.testing.assert_array_equal(values, index.astype(np.int64))
    # Sorting packed keys == stable sort of reference keys.
    order = np.argsort((tile << np.uint64(32)) | depth, kind="stable")
    np.testing.assert_array_equal(layout.to_reference(np.sort(packed))[0], ref_keys[order])
    assert not KeyLayout.choose(3_000_000, 1 << 16).packed  # 22 + 31 + 16 bits > 64


# ------------------------------------------------------------------------------ GPU
def test_integer_stages_match_reference(ctx):
    scene, settings = random_scene(3000, 7, degree=1, **IN_DEPTH), RenderSettings()
    renderer = TileRenderer(ctx, scene, settings)
    try:
        got = renderer.debug_stages(view_for(renderer, CAM))
    finally:
        renderer.release()
    proj = project(scene, CAM, settings, np.float32)
    assert_stages_match_reference(got, proj, min_keys=5000)


def test_unpacked_key_layout_matches_reference(ctx, monkeypatch, artifacts_dir):
    """The fallback for huge scenes (reference key layout, stable argsort with values)."""
    monkeypatch.setattr(tile_mod.KeyLayout, "choose", classmethod(lambda cls, n, t: cls(32, 0, False)))
    scene, settings = random_scene(2000, 3, degree=1, **IN_DEPTH), RenderSettings()
    renderer = TileRenderer(ctx, scene, settings)
    try:
        got = renderer.debug_stages(view_for(renderer, CAM))
        image = draw(renderer, CAM).rgba
    finally:
        renderer.release()
    proj = project(scene, CAM, settings, np.float32)
    keys, values = sort(*emit_keys(proj))
    np.testing.assert_array_equal(got.keys, keys)
    np.testing.assert_array_equal(got.values, values)
    assert_close(image, render_reference(scene, CAM, settings).rgba, TOL, "tile_unpacked", artifacts_dir)


def test_emit_in_several_dispatches_matches_reference(ctx, monkeypatch):
    """Rectangles larger than TILE_EMIT_CHUNK tiles are emitted over several dispatches; the
    keys and their order stay the reference's."""
    monkeypatch.setattr(tile_mod, "TILE_EMIT_CHUNK", 3)
    scene, settings = random_scene(2000, 3, degree=1, **IN_DEPTH), RenderSettings()
    renderer = TileRenderer(ctx, scene, settings)
    try:
        got = renderer.debug_stages(view_for(renderer, CAM))
    finally:
        renderer.release()
    assert got.tiles_touched.max() > 3 * 3                      # at least 4 dispatches
    proj = project(scene, CAM, settings, np.float32)
    assert_stages_match_reference(got, proj, min_keys=5000)


@pytest.mark.parametrize("surfels", [False, True], ids=["3dgs", "surfels"])
def test_list_passes_equal_one_pass(ctx, monkeypatch, surfels):
    """Tiles whose lists are longer than TILE_LIST_CHUNK are blended in several passes, the
    pixel state (C, T, stopped, D) carried in the output buffers in float32: the same values
    one pass computes, so the images are identical, bit for bit (stopped pixels included)."""
    if surfels:
        scene = random_scene(3000, 7, degree=1, **SURFELS)
        cam = Camera.from_fov(128, 96, 60.0, SURFELS_POSE)
    else:
        scene, cam = random_scene(3000, 11, degree=1, **IN_DEPTH), CAM
    settings = RenderSettings(background=(0.2, 0.4, 0.9))
    renderer = TileRenderer(ctx, scene, settings)
    try:
        one = draw(renderer, cam, depth=True)
        ranges = renderer.debug_stages(view_for(renderer, cam)).ranges
        longest = int((ranges[:, 1] - ranges[:, 0]).max())
        monkeypatch.setattr(tile_mod, "TILE_LIST_CHUNK", 100)  # up to ~10 passes
        renderer.programs = type(renderer.programs)(ctx)      # recompile with the new define
        many = draw(renderer, cam, depth=True)
    finally:
        renderer.release()
    assert longest > 400 and (one.rgba[..., 3] > 0.999).any()   # passes, and near-stopped pixels
    np.testing.assert_array_equal(many.rgba, one.rgba)
    np.testing.assert_array_equal(many.depth, one.depth)


@pytest.mark.parametrize("name, settings, camera, sh_degree", [
    ("default", RenderSettings(), CAM, 1),
    ("aa_bg_sh3", RenderSettings(antialias=True, background=(0.2, 0.4, 0.9)), CAM, 3),
    ("sh_cap", RenderSettings(sh_degree=1, background=(1.0, 1.0, 1.0)), CAM, 3),
    ("partial_tiles", RenderSettings(), Camera.from_fov(101, 77, 60.0), 1),
    ("orthographic", RenderSettings(near=0.5), Camera.orthographic(128, 96, 24.0), 0),
])
def test_image_matches_reference(ctx, artifacts_dir, name, settings, camera, sh_degree):
    scene = random_scene(3000, 11, degree=sh_degree, **IN_DEPTH)
    got, ref = render_pair(ctx, scene, camera, settings)
    assert got.rgba.shape == (camera.height, camera.width, 4) and got.rgba.dtype == np.float32
    assert ref.alpha.max() > 0.9  # the image is not empty
    assert_close(got.rgba, ref.rgba, TOL, f"tile_{name}", artifacts_dir)
    assert_close(got.depth, ref.depth, image_tol(DEPTH_TOL_REL) * float(ref.depth.max()),  # GPU: a flip's share
                 f"tile_{name}_depth", artifacts_dir)


def test_empty_and_all_culled_scenes_give_background(ctx):
    bg = (0.25, 0.5, 0.75)
    expected = np.broadcast_to(np.array([*bg, 0.0], np.float32), (96, 128, 4))
    behind = random_scene(500, 5, degree=1, **IN_DEPTH)
    behind = Scene(behind.means * np.float32([1, 1, -1]), behind.quats, behind.log_scales,
                   behind.opacity_logits, behind.sh)  # every splat behind the camera
    empty = random_scene(1, 5, degree=1, **IN_DEPTH).subset(np.zeros(1, bool))
    for scene in (behind, empty):
        renderer = TileRenderer(ctx, scene, RenderSettings(background=bg))
        try:
            got = draw(renderer, CAM).rgba
            assert renderer.last_times.n_keys == 0
        finally:
            renderer.release()
        np.testing.assert_array_equal(got, expected)


def test_renderer_dispatches_tile_kind(ctx):
    scene = random_scene(300, 2, degree=1, **IN_DEPTH)
    with Renderer(ctx) as r:
        got = r.render(scene, CAM, RenderSettings(), RendererKind.TILE)
        times = r.renderer_for(scene, RenderSettings(), RendererKind.TILE).last_times
    assert got.shape == (96, 128, 4) and got[..., 3].max() > 0.5
    assert times.total >= times.rasterize > 0.0


def test_moving_camera_re_sorts(ctx, artifacts_dir):
    """The same renderer must follow a new pose (no stale keys or order)."""
    scene = random_scene(1500, 9, degree=1, **IN_DEPTH)
    renderer = TileRenderer(ctx, scene, RenderSettings())
    try:
        for azimuth in (170.0, 200.0):
            cam = Camera.from_fov(96, 80, 60.0, orbit(np.array([0.0, 0.0, 5.0]), 6.0, azimuth, 10.0))
            got = draw(renderer, cam).rgba
            assert got[..., 3].max() > 0.5
            assert_close(got, render_reference(scene, cam).rgba, TOL, f"tile_orbit_{azimuth:g}",
                         artifacts_dir)
    finally:
        renderer.release()


@pytest.mark.slow
def test_donut_matches_reference(ctx, shared_scenes, artifacts_dir):
    """The real donut (45k splats, SH degree 0), default camera, 256 x 192."""
    scene = load_scene(shared_file(shared_scenes, "ply/donut_sh0.ply"))
    camera = default_camera(scene, 256, 192)
    got, ref = render_pair(ctx, scene, camera, RenderSettings())
    assert ref.alpha.max() > 0.9
    assert_close(got.rgba, ref.rgba, TOL, "tile_donut", artifacts_dir)
