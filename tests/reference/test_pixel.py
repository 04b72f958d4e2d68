"""``splatgl pixel`` and its library (splatgl/reference/pixel.py): the listing explains the
reference's pixel exactly: its weights sum to the pixel's alpha (float32 sums: 1e-6), its
colours with their weights make the pixel's colour, and it lists the n_blended splats."""

from __future__ import annotations

import json

import numpy as np
import pytest

from helpers import IN_DEPTH, SURFELS, SURFELS_POSE, random_scene
from splatgl.cameras.camera import Camera
from splatgl.cli import main
from splatgl.errors import SplatglError
from splatgl.formats import save_scene
from splatgl.scene.settings import RenderSettings
from splatgl.reference import render_reference
from splatgl.reference.pixel import pixel_splats

SETTINGS = RenderSettings(background=(0.2, 0.3, 0.4))


@pytest.mark.parametrize("surfels", [False, True])
def test_weights_sum_to_the_pixel_alpha_and_make_its_colour(surfels):
    if surfels:
        scene, camera = random_scene(300, seed=6, **SURFELS), Camera.from_fov(40, 30, 40.0, SURFELS_POSE)
    else:
        scene, camera = random_scene(400, seed=6, **IN_DEPTH), Camera(40, 30, 36.0, 36.0, 20.0, 15.0)
    ref = render_reference(scene, camera, SETTINGS)
    checked = 0
    for y in range(0, camera.height, 3):
        for x in range(0, camera.width, 3):
            listing = pixel_splats(scene, camera, x, y, SETTINGS)
            assert len(listing.splats) == ref.n_blended[y, x]
            assert listing.weight_sum == pytest.approx(float(ref.alpha[y, x]), abs=1e-6)
            assert listing.alpha == pytest.approx(float(ref.alpha[y, x]), abs=1e-6)
            np.testing.assert_allclose(listing.color, ref.color[y, x], atol=2e-6)
            depths = [s.depth for s in listing.splats]
            if not surfels:                      # 3DGS: front to back by the sort key
                assert depths == sorted(depths)
            t = 1.0
            for s in listing.splats:             # running transmittance and weights agree
                assert s.weight == pytest.approx(s.alpha * t, rel=1e-6)
                t = s.transmittance
            checked += bool(listing.splats)
    assert checked > 40


def test_an_opaque_stack_reports_where_blending_stopped():
    n = 40
    means = np.tile([0.0, 0.0, 5.0], (n, 1)) + np.arange(n)[:, None] * [0.0, 0.0, 0.01]
    from helpers import scene_with_colors
    scene = scene_with_colors(means, [[1.0, 0, 0, 0]] * n, [[1.0, 1.0, 0.1]] * n, [0.99] * n,
                              [[0.5, 0.5, 0.5]] * n)
    camera = Camera(16, 16, 10.0, 10.0, 8.0, 8.0)
    listing = pixel_splats(scene, camera, 8, 8)
    k = len(listing.splats)
    assert 2 <= k < 5 and listing.stopped_by == k        # front to back: rows in order
    assert [s.index for s in listing.splats] == list(range(k))
    alpha = listing.splats[0].alpha                      # every splat has this alpha here
    assert listing.splats[-1].transmittance * (1 - alpha) < 1e-4 <= listing.splats[-1].transmittance
    assert f"stopped at splat {k}" in listing.table()


def test_outside_the_image_is_one_line():
    scene = random_scene(10, seed=1, **IN_DEPTH)
    with pytest.raises(SplatglError, match=r"--at 16,3: outside the 16x16 image \(columns 0..15"):
        pixel_splats(scene, Camera(16, 16, 10.0, 10.0, 8.0, 8.0), 16, 3)


def test_a_pixel_no_splat_reaches_says_so_without_an_empty_table():
    scene = random_scene(10, seed=1, **IN_DEPTH)
    listing = pixel_splats(scene, Camera(64, 64, 10.0, 10.0, 32.0, 32.0), 0, 0)
    text = listing.table()
    assert not listing.splats and text.splitlines()[0].startswith("pixel (0, 0): no splat reaches it")
    assert "index" not in text and "weights sum 0.000000 = alpha 0.000000" in text


def test_equirect_seam_copies_name_their_scene_rows():
    """A splat on the +-180 degree seam is drawn twice (its copy one turn away); either copy's
    listing names the splat's own row."""
    from splatgl.cameras.poses import look_at
    from helpers import scene_with_colors
    scene = scene_with_colors([[0.0, 0.0, 3.0], [0.0, 0.0, -3.0]], [[1.0, 0, 0, 0]] * 2,
                              [[0.4, 0.4, 0.4]] * 2, [0.9, 0.9], [[1, 0, 0], [0, 1, 0]])
    camera = Camera.equirectangular(64, 32, look_at([0, 0, 0], [0, 0, 1]))
    left, right = pixel_splats(scene, camera, 0, 16), pixel_splats(scene, camera, 63, 16)
    assert [s.index for s in left.splats] == [1] and [s.index for s in right.splats] == [1]


def test_cli_json_lists_the_pixel(tmp_path, capsys):
    scene = random_scene(300, seed=2, **IN_DEPTH)
    path = tmp_path / "s.ply"
    save_scene(path, scene)
    code = main(["pixel", str(path), "--at", "20,15", "--width", "40", "--height", "30",
                 "--background", "0.2,0.3,0.4", "--json", "-"])
    assert code == 0
    got = json.loads(capsys.readouterr().out)
    from splatgl.api import default_camera
    camera = default_camera(scene, 40, 30)
    ref = render_reference(scene, camera, SETTINGS)
    assert got["weight_sum"] == pytest.approx(float(ref.alpha[15, 20]), abs=1e-6)
    assert len(got["splats"]) == ref.n_blended[15, 20] > 0
    assert {"index", "depth", "alpha", "weight", "transmittance", "color"} <= set(got["splats"][0])
    code = main(["pixel", str(path), "--at", "20,15", "--width", "40", "--height", "30", "--limit", "2"])
    out = capsys.readouterr().out
    assert code == 0 and "more" in out and "weights sum" in out


@pytest.mark.parametrize("args, message", [
    (["--at", "40,3"], "--at 40,3: outside the 40x30 image"),
    (["--at", "x"], "expected X,Y"),
    (["--at", "1,1", "--limit", "-1"], "--limit must be 0 or more"),
    (["--at", "1,1", "--under-depth", "z"], "--under-depth describes the --under file"),
])
def test_cli_refusals_are_one_line(capsys, args, message):
    code = main(["pixel", "--width", "40", "--height", "30"] + args)
    err = capsys.readouterr().err
    assert code == 2 and message in err and len(err.strip().splitlines()) == 1


def test_viewer_click_maps_window_points_to_image_pixels():
    """Ctrl+click (splatgl/viewer/pick.py): window points to framebuffer pixels, HiDPI too."""
    from splatgl.viewer.pick import window_pixel

    assert window_pixel(10.2, 5.9, (320, 240), (320, 240)) == (10, 5)
    assert window_pixel(10.2, 5.9, (320, 240), (640, 480)) == (20, 11)   # 2x backing scale
    assert window_pixel(320.0, 5.0, (320, 240), (320, 240)) is None
    assert window_pixel(-0.5, 5.0, (320, 240), (320, 240)) is None


def _listed_and_drawn(scene, camera, settings, compat="inria"):
    """(pixel listing, reference image) pairs over a grid of pixels."""
    ref = render_reference(scene, camera, settings, compat=compat)
    step = 3
    for y in range(1, camera.height, step):
        for x in range(1, camera.width, step):
            yield pixel_splats(scene, camera, x, y, settings, compat), ref, x, y


@pytest.mark.parametrize("fields", [
    dict(order="per-pixel"),
    dict(emulation=("sort=bucket16", "low_pass=1")),
    dict(emulation=("extent=fixed", "min_alpha=0.05")),
    dict(emulation=("extent=fixed-quad", "alpha_max=0.9", "low_pass=0.1")),
    dict(emulation=("depth=distance", "half=on", "sh=0")),
    dict(order="per-pixel", emulation=("extent=opacity", "min_alpha=0.02")),
])
def test_the_listing_explains_the_image_the_options_draw(fields):
    """Issue 38 item 6: with --order per-pixel or --emulate the listing follows the same rules
    as the image (it listed the global order's contributions, 0.14 against a drawn 0.63)."""
    from splatgl.scene.emulation import parse_emulation
    fields = dict(fields)
    settings = RenderSettings(background=(0.2, 0.3, 0.4),
                              emulation=parse_emulation(fields.pop("emulation", None)), **fields)
    scene, camera = random_scene(400, seed=9, **IN_DEPTH), Camera(40, 30, 36.0, 36.0, 20.0, 15.0)
    plain = render_reference(scene, camera, RenderSettings(background=(0.2, 0.3, 0.4)))
    differs = checked = 0
    for listing, ref, x, y in _listed_and_drawn(scene, camera, settings):
        np.testing.assert_allclose(listing.color, ref.color[y, x], atol=3e-6)
        assert listing.alpha == pytest.approx(float(ref.alpha[y, x]), abs=2e-6)
        assert listing.weight_sum == pytest.approx(float(ref.alpha[y, x]), abs=2e-6)
        assert len(listing.splats) == ref.n_blended[y, x]
        differs += bool(np.abs(ref.color[y, x] - plain.color[y, x]).max() > 1e-3)
        checked += bool(listing.splats)
    assert checked > 40 and differs > 5       # the options change the image: the test bites


def test_the_per_pixel_listing_is_sorted_by_each_splats_peak():
    scene, camera = random_scene(400, seed=9, **IN_DEPTH), Camera(40, 30, 36.0, 36.0, 20.0, 15.0)
    listing = pixel_splats(scene, camera, 20, 15, RenderSettings(order="per-pixel"))
    depths = [s.depth for s in listing.splats]
    assert len(depths) > 3 and depths == sorted(depths)


def test_the_tile_renderers_window_is_explained_too():
    """A ReferenceOptions window (the tile renderer's twin) reorders the listing as it does
    the image."""
    from splatgl.reference.options import ReferenceOptions
    scene, camera = random_scene(400, seed=9, **IN_DEPTH), Camera(40, 30, 36.0, 36.0, 20.0, 15.0)
    options = ReferenceOptions(order="per-pixel", window=2)
    for listing, ref, x, y in _listed_and_drawn(scene, camera, RenderSettings(), options):
        np.testing.assert_allclose(listing.color, ref.color[y, x], atol=3e-6)
        assert len(listing.splats) == ref.n_blended[y, x]


def test_cli_per_pixel_and_emulate_match_the_reference_render(tmp_path, capsys):
    """``pixel`` with --order per-pixel / --emulate gives the colour ``render --renderer
    reference`` draws with the same options."""
    from splatgl.api import default_camera
    from splatgl.scene.emulation import parse_emulation
    scene = random_scene(300, seed=2, **IN_DEPTH)
    path = tmp_path / "s.ply"
    save_scene(path, scene)
    camera = default_camera(scene, 40, 30)
    for extra, fields in [(["--order", "per-pixel"], dict(order="per-pixel")),
                          (["--emulate", "sort=bucket16", "--emulate", "extent=fixed"],
                           dict(emulation=parse_emulation(["sort=bucket16", "extent=fixed"])))]:
        ref = render_reference(scene, camera, RenderSettings(background=(0.2, 0.3, 0.4), **fields))
        for x, y in [(20, 15), (14, 11), (25, 18)]:
            code = main(["pixel", str(path), "--at", f"{x},{y}", "--width", "40", "--height", "30",
                         "--background", "0.2,0.3,0.4", "--json", "-"] + extra)
            got = json.loads(capsys.readouterr().out)
            assert code == 0
            np.testing.assert_allclose(got["color"], ref.color[y, x], atol=3e-6)
            assert got["alpha"] == pytest.approx(float(ref.alpha[y, x]), abs=2e-6)


def test_per_pixel_with_geometry_is_refused_as_render_refuses_it():
    from splatgl.output.under import UnderLayer
    scene, camera = random_scene(50, seed=9, **IN_DEPTH), Camera(40, 30, 36.0, 36.0, 20.0, 15.0)
    under = object.__new__(UnderLayer)
    with pytest.raises(SplatglError, match="--order per-pixel draws colour, alpha and depth only"):
        pixel_splats(scene, camera, 5, 5, RenderSettings(order="per-pixel"), under=under)
