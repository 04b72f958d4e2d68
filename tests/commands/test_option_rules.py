"""Options that were accepted and ignored, and rules that differed between commands (issue 25,
item 8): each now works or is refused in one line, before any work, and nothing is written."""

from __future__ import annotations

import json

import numpy as np
import pytest

from helpers import refused
from splatgl.cli import main
from splatgl.commands._common import demo_scene_path
from splatgl.datasets import select_indices
from splatgl.errors import CameraError
from splatgl.imagefiles.images import read_image

DEMO = str(demo_scene_path())


@pytest.mark.parametrize("extra, names, verb", [
    (["--select", "0:3"], "--select", "applies"),
    (["--resume", "--fps", "24"], "--resume, --fps", "apply"),
    (["--format", "exr", "--workers", "2"], "--format, --workers", "apply"),
    (["--executor", "ray", "--ray-gpus", "1"], "--executor, --ray-gpus", "apply"),
])
def test_path_only_options_without_path(tmp_path, capsys, extra, names, verb):
    refused(capsys, tmp_path, ["render", "-o", tmp_path / "x.png", *extra],
            f"splatgl: error: {names} {verb} to --path only (many frames); without --path, "
            "render draws one view")


def test_fps_applies_to_a_video_only(tmp_path, capsys):
    refused(capsys, tmp_path, ["render", DEMO, "--path", "orbit:2", "--fps", "24", "-o",
                               tmp_path / "f"],
            f"splatgl: error: --fps sets a video's frame rate; -o {tmp_path / 'f'} writes image "
            "files, which hold none (give a .mp4 or .mov to write a video)")


@pytest.mark.parametrize("out, what", [("o.mp4", "a video"),
                                       ("f_%03d.png", "a pattern whose suffix names the image type")])
def test_format_applies_to_a_folder_only(tmp_path, capsys, out, what):
    target = tmp_path / out
    refused(capsys, tmp_path, ["render", "--path", "orbit:2", "--format", "exr", "-o", target],
            f"splatgl: error: --format exr: -o {target} is {what}; --format picks the image type "
            "of frames written into a folder")


def test_depth_png_with_separate_stereo_eyes(tmp_path, capsys):
    """--depth-png with --stereo-layout separate was never written; now one per eye."""
    assert main(["render", "-o", str(tmp_path / "v.png"), "--depth-png", str(tmp_path / "d.png"),
                 "--stereo", "0.2", "--stereo-layout", "separate", "--width", "48",
                 "--height", "32"]) == 0
    out = capsys.readouterr().out
    assert sorted(p.name for p in tmp_path.iterdir()) == ["d_left.png", "d_right.png",
                                                          "v_left.png", "v_right.png"]
    assert f"wrote {tmp_path / 'd_left.png'} (expected depth)" in out
    left, right = read_image(tmp_path / "d_left.png"), read_image(tmp_path / "d_right.png")
    assert left.shape[1] == 48 and not np.array_equal(left, right)


def test_path_command_refuses_zero_fps_and_keeps_files_without_force(tmp_path, capsys):
    out = tmp_path / "p.json"
    refused(capsys, tmp_path, ["path", "orbit", DEMO, "--fps", "0", "-o", out],
            "splatgl: error: argument --fps: must be a finite number > 0, got '0' "
            "(see splatgl path orbit --help)")
    refused(capsys, tmp_path, ["render", "--path", "orbit:2", "--fps", "0", "-o", tmp_path / "o.mp4"],
            "splatgl: error: argument --fps: must be a finite number > 0, got '0' "
            "(see splatgl render --help)")
    out.write_text("{}")
    refused(capsys, tmp_path, ["path", "orbit", DEMO, "--frames", "2", "-o", out],
            f"splatgl: error: -o {out}: exists (use --force to replace it)")
    assert main(["path", "orbit", DEMO, "--frames", "2", "-o", str(out), "--force"]) == 0
    assert json.loads(out.read_text())["frames"] == 2


def test_lod_output_must_be_a_ply(tmp_path, capsys):
    refused(capsys, tmp_path, ["lod", DEMO, "-o", tmp_path / "out.png"],
            f"splatgl: error: {tmp_path / 'out.png'}: a level-of-detail file is an INRIA PLY; "
            "name it *.lod.ply")


def test_select_refuses_out_of_range_slices_like_indices():
    assert select_indices("0:10:3", 10) == [0, 3, 6, 9]
    assert select_indices("-3:", 10) == [7, 8, 9]
    with pytest.raises(CameraError, match=r"^src: --select '0:200': stop 200 out of range "
                                          r"\(150 cameras\)$"):
        select_indices("0:200", 150, "src")
    with pytest.raises(CameraError, match=r"^src: --select index 150 out of range \(150 cameras\)$"):
        select_indices("150", 150, "src")
    with pytest.raises(CameraError, match=r"start -11 out of range \(10 cameras\)"):
        select_indices("-11:", 10, "src")


def test_orbit_path_takes_up_and_refuses_distance(tmp_path, capsys):
    """--up and --distance with --path were dropped without a word: an orbit now turns about
    --up (its frame 0 is the default camera's view, as documented), and --distance is refused."""
    from splatgl.cli import build_parser
    from splatgl.commands._common import camera_from_args
    from splatgl.commands._render_path import path_cameras
    from splatgl.formats import load_scene

    scene = load_scene(DEMO)
    argv = ["render", "--path", "orbit:3", "--up", "+z", "--width", "64", "--height", "48", "-o", "f/"]
    cams, _, _ = path_cameras(build_parser().parse_args(argv), scene)
    home = camera_from_args(build_parser().parse_args(["render", "--up", "+z", "--width", "64",
                                                       "--height", "48", "-o", "x.png"]), scene)
    np.testing.assert_allclose(cams[0].world_to_camera, home.world_to_camera, atol=1e-9)
    refused(capsys, tmp_path, ["render", "--path", "orbit:2", "--distance", "2", "-o", tmp_path / "f/"],
            "splatgl: error: --distance places the default camera; with --path it has no effect "
            "(an orbit's radius: splatgl path orbit --radius)")


# Issue 38: options only some renderers read were accepted and ignored by the others (the
# quad path's --extent, --sort, --precision ... on the cpu and reference renderers) while
# --emulate was refused there; one table (each entry's reads, splatgl/renderers/registry.py) now rules them all.
@pytest.mark.parametrize("renderer, option, value, drawn_by, use", [
    ("cpu", "--extent", "square", "quad renderer", "quad"),
    ("reference", "--extent", "fast", "quad renderer", "quad"),
    ("cpu", "--sort", "bucket16", "quad renderer", "quad"),
    ("reference", "--precision", "rgba8", "quad renderer", "quad"),
    ("tile", "--precision", "rgba16f", "quad renderer", "quad"),
    ("cpu", "--preprocess", "vertex", "quad renderer", "quad"),
    ("tile", "--early-stop", "on", "quad renderer", "quad"),
    ("reference", "--gpu-storage", "compact", "quad and tile renderers", "quad or tile"),
    ("cpu", "--gpu-storage", "half-sh", "quad and tile renderers", "quad or tile"),
])
def test_an_option_the_renderer_ignores_is_refused(tmp_path, capsys, renderer, option, value,
                                                   drawn_by, use):
    refused(capsys, tmp_path, ["render", DEMO, "-o", tmp_path / "x.png", "--renderer", renderer,
                               option, value],
            f"splatgl: error: {option} {value} applies to the {drawn_by} only, not the "
            f"{renderer} renderer, which would ignore it (use --renderer {use}, or leave "
            f"{option} out)")


def test_the_options_defaults_are_accepted_by_every_renderer():
    from splatgl.cli import build_parser
    from splatgl.commands._common import check_convention
    for renderer in ("quad", "tile", "reference", "cpu"):
        args = build_parser().parse_args(
            ["render", "-o", "x.png", "--renderer", renderer, "--extent", "ellipse", "--sort",
             "exact", "--precision", "rgba32f", "--preprocess", "compute", "--early-stop",
             "auto", "--gpu-storage", "float32", "--order", "global", "--order-window", "32"])
        check_convention(args, renderer)


def test_a_path_refuses_them_too(tmp_path, capsys):
    refused(capsys, tmp_path, ["render", DEMO, "--path", "orbit:2", "-o", tmp_path / "f/",
                               "--renderer", "cpu", "--sort", "bucket16"],
            "splatgl: error: --sort bucket16 applies to the quad renderer only, not the cpu "
            "renderer, which would ignore it (use --renderer quad, or leave --sort out)")


def test_the_per_pixel_order_on_the_cpu_renderer_names_it(tmp_path, capsys):
    """It was refused as "not the quad path" for the cpu renderer."""
    refused(capsys, tmp_path, ["render", DEMO, "-o", tmp_path / "x.png", "--renderer", "cpu",
                               "--order", "per-pixel"],
            "splatgl: error: --order per-pixel is drawn by the tile renderer and the NumPy "
            "reference, not the cpu renderer (use --renderer tile or reference)")


@pytest.mark.parametrize("renderer", ["tile", "reference"])
def test_order_window_without_the_per_pixel_order(tmp_path, capsys, renderer):
    refused(capsys, tmp_path, ["render", DEMO, "-o", tmp_path / "x.png", "--renderer", renderer,
                               "--order-window", "8"],
            "splatgl: error: --order-window 8 applies to --order per-pixel only; the global "
            "order has no window (add --order per-pixel)")


def test_order_window_on_the_reference_which_sorts_exactly(tmp_path, capsys):
    refused(capsys, tmp_path, ["render", DEMO, "-o", tmp_path / "x.png", "--renderer",
                               "reference", "--order", "per-pixel", "--order-window", "8"],
            "splatgl: error: --order-window 8 applies to the tile renderer only, not the "
            "reference renderer, which would ignore it (use --renderer tile, or leave "
            "--order-window out)")


def test_compare_image_refuses_a_renderer_under_test(tmp_path, capsys):
    image = tmp_path / "theirs.png"
    image.write_bytes(b"not read")
    refused(capsys, tmp_path, ["compare", DEMO, "--image", image, "--renderer", "tile"],
            "splatgl: error: --renderer tile: with --image the image is under test, not a "
            "renderer (--against picks what it is measured against)")
    refused(capsys, tmp_path, ["compare", DEMO, "--image", image, "--extent", "square"],
            "splatgl: error: --extent square applies to the quad renderer only, not the "
            "reference renderer, which would ignore it (use --renderer quad, or leave "
            "--extent out)")


def test_pixel_refuses_what_the_reference_ignores(tmp_path, capsys):
    refused(capsys, tmp_path, ["pixel", DEMO, "--at", "1,1", "--width", "8", "--height", "8",
                               "--sort", "bucket16"],
            "splatgl: error: --sort bucket16 applies to the quad renderer only, not the "
            "reference renderer, which would ignore it (pixel explains the NumPy reference's "
            "image; leave --sort out)")


def test_the_api_refuses_them_as_the_cli_does():
    from splatgl import render
    from splatgl.errors import SplatglError
    from splatgl.formats import load_scene
    from splatgl.scene.settings import RenderSettings
    with pytest.raises(SplatglError, match=r"^--extent square applies to the quad renderer only, "
                                           r"not the reference renderer"):
        render(load_scene(DEMO), None, RenderSettings(extent="square"), "reference")


# A benchmark's own options given without the flag that runs it were silently ignored (the
# scene benchmark ran instead): bench --target-fps without --interactive, --lod-* without --lod.
@pytest.mark.parametrize("extra, line", [
    (["--target-fps", "5"], "--target-fps: an option of the interactive benchmark; add --interactive"),
    (["--scale", "--target-fps", "5"],
     "--target-fps: an option of the interactive benchmark; add --interactive"),
    (["--lod-thresholds", "1", "--lod-paths", "fine"],
     "--lod-thresholds, --lod-paths: options of the level-of-detail benchmark; add --lod"),
    (["--interactive", "--lod-budgets", "1M"],
     "--lod-budgets: an option of the level-of-detail benchmark; add --lod"),
    (["--lod-blend", "2", "--memory", "1G"],
     "--lod-blend: an option of the level-of-detail benchmark; add --lod"),
    (["--sizes", "1M"], "--sizes: an option of the scale and level-of-detail benchmarks; add "
                        "--scale or --lod"),
    (["--lod", "--sh3-sizes", "1M"], "--sh3-sizes: an option of the scale benchmark; add --scale"),
])
def test_bench_mode_options_without_their_mode(tmp_path, capsys, extra, line):
    refused(capsys, tmp_path, ["bench", "--quick", "--out", tmp_path / "b", *extra],
            f"splatgl: error: {line}")


def test_bench_mode_options_with_their_mode_pass_the_check():
    from splatgl.cli import build_parser
    from splatgl.commands._bench_modes import check_mode_options
    for argv in (["--interactive", "--target-fps", "5"], ["--lod", "--lod-paths", "fine", "--sizes", "1M"],
                 ["--scale", "--sizes", "1M", "--sh3-sizes", "none"], ["--popping", "--popping-window", "4"]):
        check_mode_options(build_parser().parse_args(["bench", *argv]))


def test_lod_options_name_themselves_without_a_level_of_detail_scene(tmp_path, capsys):
    """render's --lod-* read a .lod.ply (which is what turns level of detail on); without one
    the refusal named 'None' (the bundled demo) and not the option."""
    refused(capsys, tmp_path, ["render", "-o", tmp_path / "x.png", "--lod-threshold", "1",
                               "--lod-blend", "2"],
            "splatgl: error: the bundled demo demo.ply: not a level-of-detail file, which "
            "--lod-threshold, --lod-blend read; build one with 'splatgl lod SCENE -o SCENE.lod.ply'")
