"""Library first, CLI thin (issue 26, item 5): each rule ``splatgl render`` applies lives in the
library, so the Python API refuses, frames and defaults as the command line does.

Each test runs one rule both ways: through the Python API and through ``splatgl.cli.main``,
and asserts the same message, camera or setting.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

import splatgl
from helpers import IN_VIEW, random_scene
from splatgl.cli import build_parser, main
from splatgl.commands._common import camera_from_args, demo_scene_path, settings_from_args
from splatgl.errors import CameraError, SplatglError
from splatgl.formats import save_scene
from splatgl.imagefiles.images import read_image

DEMO = demo_scene_path()


def cli_error(capsys, *argv) -> str:
    """The one error line ``splatgl ARGV`` prints (exit code 2), without its prefix."""
    assert main([str(a) for a in argv]) == 2
    err = capsys.readouterr().err
    assert err.startswith("splatgl: error: ") and err.count("\n") == 1, err
    return err[len("splatgl: error: "):-1]


def cli_camera(*argv, scene=None):
    """The camera ``splatgl render ARGV`` renders (of ``scene``, default the demo)."""
    args = build_parser().parse_args(["render", *map(str, argv), "-o", "x.png"])
    scene = scene if scene is not None else splatgl.load_scene(args.scene or DEMO)
    return camera_from_args(args, scene, settings_from_args(args))


# ------------------------------------------------------------------ convention gsplat


@pytest.mark.parametrize("kind", ["quad", "tile"])
def test_gpu_renderers_refuse_the_gsplat_convention_as_the_cli_does(kind, capsys, tmp_path):
    """The quad and tile renderers draw the inria rules only: RenderSettings(convention=gsplat)
    was ignored silently by the library (only the CLI refused it)."""
    scene = random_scene(50, **IN_VIEW)
    camera = splatgl.Camera.from_fov(32, 24, 60.0)
    gsplat = splatgl.RenderSettings(convention="gsplat")
    with pytest.raises(SplatglError) as api:
        splatgl.render(scene, camera, gsplat, kind=kind)
    with splatgl.Renderer() as r, pytest.raises(SplatglError) as many:
        next(r.render_many(scene, [camera], gsplat, kind))
    line = cli_error(capsys, "render", "--convention", "gsplat", "--renderer", kind,
                     "--width", 32, "--height", 24, "-o", tmp_path / "x.png")
    assert str(api.value) == str(many.value) == line == (
        f"--convention gsplat applies to the NumPy reference only; the {kind} renderer follows "
        "the inria rules (use --renderer reference)")
    rgba = splatgl.render(scene, camera, gsplat, kind="reference")   # the reference draws it
    assert rgba.shape == (24, 32, 4) and rgba[..., 3].max() > 0.1


def test_compare_draws_the_gpu_side_with_the_inria_rules(capsys):
    """compare --convention gsplat measures the quad path (inria rules) against the gsplat
    reference: the library's refusal must not stop it."""
    assert main(["compare", "--convention", "gsplat", "--width", "48", "--height", "32",
                 "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["psnr"] > 20.0


def test_eval_refuses_the_gsplat_convention_before_the_work(capsys, tmp_path):
    """eval took --convention gsplat with the quad renderer and drew the inria rules."""
    line = cli_error(capsys, "eval", "--dataset", tmp_path / "none", "--convention", "gsplat")
    assert line.startswith("--convention gsplat applies to the NumPy reference only; the quad")


# ------------------------------------------------------------------ the default camera


def same_camera(a, b) -> None:
    assert (a.width, a.height, a.projection, a.model) == (b.width, b.height, b.projection, b.model)
    np.testing.assert_allclose([a.fx, a.fy, a.cx, a.cy], [b.fx, b.fy, b.cx, b.cy], rtol=1e-12)
    np.testing.assert_allclose(a.world_to_camera, b.world_to_camera, atol=1e-12)


@pytest.mark.parametrize("kwargs, argv", [
    ({}, []),
    ({"width": 64, "height": 48, "fov_degrees": 70.0, "distance_scale": 0.5},
     ["--width", 64, "--height", 48, "--fov", 70, "--distance", 0.5]),
    ({"projection": "orthographic"}, ["--orthographic"]),
    ({"projection": "orthographic", "width": 96, "distance_scale": 2.0},
     ["--projection", "orthographic", "--width", 96, "--distance", 2]),
    ({"projection": "fisheye", "fov_degrees": 200.0}, ["--projection", "fisheye", "--fov", 200]),
    ({"projection": "fisheye", "height": 50}, ["--projection", "fisheye", "--height", 50]),
    ({"projection": "equirectangular"}, ["--projection", "equirectangular"]),
    ({"projection": "equirectangular", "width": 100}, ["--projection", "equirectangular", "--width", 100]),
    ({"up": "+z"}, ["--up", "+z"]),
])
def test_default_camera_is_the_clis_for_every_model(kwargs, argv):
    """Size, field of view, framing and up of splatgl.default_camera are render's defaults."""
    scene = splatgl.load_scene(DEMO)
    same_camera(splatgl.default_camera(scene, **kwargs), cli_camera(*argv))


def test_default_sizes_come_from_the_model():
    """1280x720, but a panorama is 2:1 (its height, or half its width)."""
    scene = splatgl.load_scene(DEMO)
    size = lambda **kw: (lambda c: (c.width, c.height))(splatgl.default_camera(scene, **kw))  # noqa: E731
    assert size() == (1280, 720) and size(width=640) == (640, 720)
    assert size(projection="equirectangular") == (1440, 720)
    assert size(projection="equirectangular", height=24) == (48, 24)
    assert size(projection="equirectangular", width=101) == (101, 50)


def test_orthographic_default_camera_frames_the_scene():
    """Its narrower side spans 2.1 robust radii (was only in the CLI: the library had no
    orthographic default camera)."""
    scene = random_scene(400, spread=(2.0, 1.0, 1.0))
    cam = splatgl.default_camera(scene, 120, 80, projection="orthographic")
    assert cam.projection == "orthographic" and cam.fx == cam.fy
    assert cam.fx == pytest.approx(80 / (2.1 * scene.robust_radius), rel=1e-12)
    twice = splatgl.default_camera(scene, 120, 80, distance_scale=2.0, projection="orthographic")
    assert twice.fx == pytest.approx(cam.fx / 2, rel=1e-12)


@pytest.mark.parametrize("kwargs, argv", [
    ({"projection": "equirectangular", "fov_degrees": 120.0},
     ["--projection", "equirectangular", "--fov", 120]),
    ({"projection": "orthographic", "fov_degrees": 40.0}, ["--orthographic", "--fov", 40]),
    ({"projection": "fisheye", "fov_degrees": 400.0}, ["--projection", "fisheye", "--fov", 400]),
    ({"fov_degrees": 180.0}, ["--fov", 180]),
])
def test_default_camera_refuses_fields_of_view_as_the_cli_does(kwargs, argv, capsys, tmp_path):
    scene = splatgl.load_scene(DEMO)
    with pytest.raises(CameraError) as api:
        splatgl.default_camera(scene, **kwargs)
    assert str(api.value) == cli_error(capsys, "render", *argv, "-o", tmp_path / "x.png")
    with pytest.raises(CameraError, match=r"^projection must be one of 'perspective', "):
        splatgl.default_camera(scene, projection="cylinder")


def test_default_camera_takes_the_up_of_the_cameras_beside_the_scene(tmp_path):
    """A cameras.json beside the scene file sets the default view's up in the library too
    (scene.source), as it does for splatgl render."""
    from test_up import orbit_cameras

    path = tmp_path / "out" / "point_cloud" / "scene.ply"
    path.parent.mkdir(parents=True)
    save_scene(path, random_scene(200, spread=(1.0, 1.0, 0.3)))
    (tmp_path / "out" / "cameras.json").write_text(json.dumps(orbit_cameras([0, 0, 1.0])))
    scene = splatgl.load_scene(path)
    assert scene.source.path == path
    cam = splatgl.default_camera(scene, 64, 48)
    same_camera(cam, cli_camera(path, "--width", 64, "--height", 48, scene=scene))
    assert _image_up(cam)[2] > 0.9          # z up in the image, not the -y fallback
    assert _image_up(splatgl.default_camera(scene, 64, 48, up="-y"))[1] < -0.9
    assert _image_up(splatgl.default_camera(scene.subset(slice(0, 100)), 64, 48))[1] < -0.9
    with pytest.raises(CameraError, match=r"^up must be one of \+y, -y, \+z, -z or a 3-vector"):
        splatgl.default_camera(scene, up="z")


def _image_up(camera) -> np.ndarray:
    """The world direction pointing up in ``camera``'s image, projected off its view axis."""
    up = -camera.rotation[1]
    return up / np.linalg.norm(up)


# ------------------------------------------------------------------ settings from file tags


def test_a_mip_tagged_scene_renders_with_antialias_by_default(tmp_path, capsys):
    """A file tagged as trained with antialiasing (here a PLY 'SplatRenderMode: mip' comment):
    splatgl render turns --antialias on; so do default_settings and splatgl.render."""
    scene = random_scene(300, **IN_VIEW)
    tagged = tmp_path / "mip.ply"
    save_scene(tagged, scene)
    tagged.write_bytes(tagged.read_bytes().replace(b"comment written by splatgl",
                                                   b"comment SplatRenderMode: mip", 1))
    plain = tmp_path / "plain.ply"
    save_scene(plain, scene)
    loaded = splatgl.load_scene(tagged)
    assert loaded.source.antialias_tag == "PLY comment 'SplatRenderMode: mip'"
    settings = splatgl.default_settings(loaded)
    assert settings == splatgl.RenderSettings(antialias=True)
    args = build_parser().parse_args(["render", str(tagged), "-o", "x.png"])
    assert settings_from_args(args) == settings
    assert "mip.ply: PLY comment 'SplatRenderMode: mip': rendering with --antialias" in capsys.readouterr().err
    assert splatgl.default_settings(loaded, antialias=False).antialias is False
    assert splatgl.default_settings(splatgl.load_scene(plain)).antialias is False
    assert splatgl.default_settings(scene) == splatgl.RenderSettings()   # built in memory
    camera = splatgl.Camera.from_fov(40, 30, 60.0)
    on = splatgl.render(loaded, camera, splatgl.RenderSettings(antialias=True), kind="reference")
    off = splatgl.render(loaded, camera, splatgl.RenderSettings(), kind="reference")
    assert np.abs(on - off).max() > 1e-3
    np.testing.assert_array_equal(splatgl.render(loaded, camera, kind="reference"), on)


def test_render_without_camera_or_settings_draws_what_the_cli_draws(tmp_path, capsys):
    """splatgl.render(scene) is `splatgl render SCENE` without options (same camera, same
    settings): the same 8-bit image."""
    out = tmp_path / "x.png"
    assert main(["render", str(DEMO), "-o", str(out)]) == 0
    capsys.readouterr()
    rgba = splatgl.render(splatgl.load_scene(DEMO))
    assert rgba.shape == (720, 1280, 4)
    np.testing.assert_allclose(read_image(out), np.clip(rgba[..., :3], 0, 1), atol=0.5 / 255 + 1e-6)


# ------------------------------------------------------------------ level of detail


def test_lod_renders_from_plain_values_as_the_cli_does(tmp_path, capsys):
    """render_lod takes a tree, a camera, settings and LodSettings (it took the CLI's
    argparse.Namespace); stereo and the gsplat convention are refused by the library too."""
    from splatgl.lod.frames import LodFrames, render_lod
    from splatgl.lod.io import read_lod
    from splatgl.lod.selection import LodSettings
    from splatgl.renderers.stereo import StereoLayout, StereoRenderer

    path = tmp_path / "demo.lod.ply"
    assert main(["lod", str(DEMO), "-o", str(path)]) == 0
    out = tmp_path / "one.png"
    assert main(["render", str(path), "--lod-budget", "300", "--width", "64", "--height", "48",
                 "-o", str(out)]) == 0
    capsys.readouterr()
    tree, scene = read_lod(path), splatgl.load_scene(path)
    got, times, _ = render_lod(tree, splatgl.default_camera(scene, 64, 48),
                               splatgl.default_settings(scene), LodSettings(budget=300))
    assert 0 < times.cut_nodes <= 300
    np.testing.assert_allclose(read_image(out), np.clip(got.rgba[..., :3], 0, 1), atol=0.5 / 255 + 1e-6)
    line = cli_error(capsys, "render", path, "--lod-budget", 300, "--stereo", 0.1, "--path",
                     "orbit:2", "-o", tmp_path / "f")
    with LodFrames(tree, splatgl.RenderSettings(), LodSettings()) as frames:
        with pytest.raises(SplatglError) as stereo:
            StereoRenderer(frames, 0.1, StereoLayout.SIDE_BY_SIDE)
    assert str(stereo.value) == line == LodFrames.stereo_refusal
    with pytest.raises(SplatglError, match=r"^--convention gsplat applies to the NumPy reference "
                                           r"only; the quad renderer follows the inria rules"):
        LodFrames(tree, splatgl.RenderSettings(convention="gsplat"), LodSettings())
    with pytest.raises(SplatglError, match=r"^--lod-budget must be at least 1, got 0"):
        LodSettings(budget=0)


# ------------------------------------------------------------------ argparse lives in commands/


def test_argparse_only_in_the_command_line_modules():
    """Library modules take plain values; option parsing is splatgl/commands/ and cli.py
    (lod/command.py, measure/bench/lod_bench.py, bench/scale_cli.py, measure/bench/gpu_probe.py and
    measure/bench/scale_report.py parsed or took argparse.Namespace; tasks/executor.py's options moved
    to commands/_executor.py)."""
    import re
    from pathlib import Path

    root = Path(splatgl.__file__).parent
    found = {p.relative_to(root).as_posix() for p in root.rglob("*.py")
             if re.search(r"^\s*(import argparse|from argparse import)", p.read_text(), re.M)
             and p.relative_to(root).parts[0] != "commands"}
    assert found <= {"cli.py"}, found


def test_bench_mode_options_are_refused_before_the_work(capsys):
    """The --lod and --scale options (now parsed in commands/_bench_modes.py) still refuse bad
    values in one line before measuring anything."""
    assert cli_error(capsys, "bench", "--lod", "--lod-blend", "2,0.5") == (
        "--lod-blend: bands are ratios of at least 1, got '2,0.5'")
    assert cli_error(capsys, "bench", "--lod", "--lod-thresholds", "1,x") == (
        "--lod-thresholds: expected comma-separated numbers, got '1,x'")
    assert cli_error(capsys, "bench", "--scale", "--sizes", "1M,lots") == (
        "--sizes: 'lots' is not a size (e.g. 0.1M, 300k, 6M)")


# ------------------------------------------------------------------ easy mistakes through the API


@pytest.mark.parametrize("field, value, accepted", [
    ("precision", "rgba64", "rgba32f, rgba16f, rgba8"),
    ("extent", "circle", "ellipse, square, fast"),
    ("sort_key", "radix", "exact, bucket16, gpu"),
    ("preprocess", None, "vertex, compute"),
    ("convention", "INRIA", "inria, gsplat"),
    ("gpu_storage", "half", "float32, half-sh, compact"),
    ("early_stop", "sometimes", "auto, on, off"),
    ("order", ["global"], "global, per-pixel"),
])
def test_render_settings_name_the_field_the_value_and_the_accepted_values(field, value, accepted):
    """RenderSettings(precision="rgba64") said only "'rgba64' is not a valid Precision"; the
    accepted values are the CLI's choices for the option."""
    with pytest.raises(SplatglError) as err:
        splatgl.RenderSettings(**{field: value})
    assert str(err.value) == f"RenderSettings {field}: {value!r} is not one of {accepted}"
    assert isinstance(err.value, ValueError)   # what the enum raised before


@pytest.mark.parametrize("field, value, message", [
    ("background", "abc", "expected 3 numbers (R, G, B), got 'abc'"),
    ("background", (0, 0, "x"), "expected a number, got 'x'"),
    ("order_window", "x", "expected a number, got 'x'"),
    ("resort_interval", None, "expected a number, got None"),
    ("sh_degree", "2", "expected a number, got '2'"),
    ("near", True, "expected a number, got True"),
])
def test_render_settings_numbers_name_the_field(field, value, message):
    """RenderSettings(background="abc") was "could not convert string to float: 'a'",
    sh_degree="2" a TypeError from a comparison: each now names the field and the value."""
    with pytest.raises(SplatglError) as err:
        splatgl.RenderSettings(**{field: value})
    assert str(err.value) == f"RenderSettings {field}: {message}"


@pytest.mark.parametrize("call, caller", [
    (lambda s: splatgl.render(s), "render"),
    (lambda s: splatgl.default_camera(s, 64, 48), "default_camera"),
    (lambda s: splatgl.default_settings(s), "default_settings"),
    (lambda s: splatgl.Renderer().render(s), "Renderer.render"),
    (lambda s: splatgl.Renderer().render_layers(s), "Renderer.render_layers"),
    (lambda s: splatgl.Renderer().render_many(s, []), "Renderer.render_many"),   # at the call
    (lambda s: splatgl.Renderer().renderer_for(s, splatgl.RenderSettings()), "Renderer.renderer_for"),
])
def test_the_api_says_a_scene_is_needed_where_it_is_given_something_else(call, caller):
    """splatgl.render("x.splat") was AttributeError: 'str' object has no attribute
    'antialias_tag'; splatgl.render(None): 'NoneType' object has no attribute 'source'."""
    need = f"{caller}: scene must be a splatgl Scene (load one with splatgl.load_scene(path)), got"
    for value, got in (("x.splat", "str 'x.splat'"), (None, "None"), (3, "int 3")):
        if value is None and caller == "default_settings":
            continue   # no scene: the settings of none
        with pytest.raises(TypeError) as err:
            call(value)
        assert str(err.value) == f"{need} {got}"
    with pytest.raises(TypeError, match=r"got ndarray array\(\[\[0\., 0\., 0\.\], \[0\., .*\.\.\.$"):
        call(np.zeros((1000, 3)))   # one line, cut short


@pytest.mark.parametrize("side, value", [("width", "abc"), ("height", 0), ("width", -3),
                                         ("height", 2.5), ("width", float("nan")),
                                         ("height", float("inf")), ("width", "800"), ("width", True)])
def test_image_sizes_from_python_are_checked_as_the_cli_checks_them(side, value, capsys, tmp_path):
    """default_camera(scene, "abc", 10) was ValueError: invalid literal for int() with base 10;
    the CLI refuses the same values (its --width/--height are argparse's whole numbers >= 1)."""
    scene = splatgl.load_scene(DEMO)
    size = {"width": 64, "height": 48, side: value}
    message = f"camera {side} must be a positive integer, got {value!r}"
    camera_file = tmp_path / "camera.json"
    splatgl.save_camera(camera_file, splatgl.default_camera(scene, 64, 48))
    for call in (lambda: splatgl.default_camera(scene, size["width"], size["height"]),
                 lambda: splatgl.Camera.from_fov(size["width"], size["height"], 60.0),
                 lambda: splatgl.default_camera(scene).resized(size["width"], size["height"]),
                 lambda: splatgl.load_camera(camera_file, **{side: value})):   # 0 was ignored
        with pytest.raises(CameraError) as err:
            call()
        assert str(err.value) == message
    if not (isinstance(value, bool) or str(value).isdigit()):   # the CLI reads "800" as 800
        assert cli_error(capsys, "render", f"--{side}", value, "-o", tmp_path / "x.png").startswith(
            f"argument --{side}: ")


def test_whole_numbers_of_any_kind_are_image_sizes():
    scene = splatgl.load_scene(DEMO)
    camera = splatgl.default_camera(scene, np.int64(64), 48.0)
    assert (camera.width, camera.height) == (64, 48) and type(camera.width) is int


def test_the_api_names_a_wrong_argument_and_how_to_make_a_right_one(tmp_path):
    """A camera file's name where a Camera goes, settings as a dict, one Camera to render_many,
    arguments swapped in save_scene / save_camera, a number as a path: each was an
    AttributeError or a pathlib TypeError from deep inside; each now says, in one line, which
    argument of which function must be what, and what it got."""
    from splatgl.edit import edit_scene, transform_scene

    scene = splatgl.load_scene(DEMO)
    cam = splatgl.default_camera(scene, 16, 12)
    cases = [
        (lambda: splatgl.render(scene, "cam.json"), "render: camera must be a splatgl Camera"),
        (lambda: splatgl.Renderer().render(scene, cam, {"background": (1, 1, 1)}),
         "Renderer.render_layers: settings must be a RenderSettings"),
        (lambda: splatgl.Renderer().render_many(scene, cam),
         "Renderer.render_many: cameras must be an iterable of Cameras (one view: "
         "Renderer.render), got Camera("),
        (lambda: splatgl.Renderer().render_layers(scene, cam, under=np.zeros((12, 16, 4))),
         "Renderer.render_layers: under must be an UnderImage"),
        (lambda: splatgl.save_scene(scene, tmp_path / "x.ply"),
         "save_scene: path must be a file path (a str or a pathlib.Path) (the scene goes "
         "second), got Scene("),
        (lambda: splatgl.save_camera(cam, tmp_path / "c.json"), "save_camera: path must be"),
        (lambda: splatgl.load_scene(123), "load_scene: path must be a file path (a str or a "
                                          "pathlib.Path), got int 123"),
        (lambda: edit_scene("x.ply"), "edit_scene: scene must be a splatgl Scene"),
        (lambda: transform_scene(scene, 5), "transform_scene: transform must be a SceneTransform"),
    ]
    for call, start in cases:
        with pytest.raises(TypeError) as err:
            call()
        assert str(err.value).startswith(start) and "\n" not in str(err.value), err.value
    assert list(tmp_path.iterdir()) == []
    moved = transform_scene(scene, {"translate": [1, 0, 0]})        # --transform's keys
    # atol: one float32 addition on coordinates of order 1 (a rounding of 6e-8)
    np.testing.assert_allclose(moved.means, scene.means + np.float32([1, 0, 0]), atol=1e-6)
