"""Options that were accepted and ignored, and rules that differed between commands (issue 25,
item 8): each now works or is refused in one line, before any work, and nothing is written."""

from __future__ import annotations

import json

import numpy as np
import pytest

from splatgl.cli import main
from splatgl.commands._common import demo_scene_path
from splatgl.datasets import select_indices
from splatgl.errors import CameraError
from splatgl.output.images import read_image

DEMO = str(demo_scene_path())


def refused(capsys, tmp_path, argv, line):
    before = sorted(p.name for p in tmp_path.iterdir())
    rc = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    assert (rc, out, err) == (2, "", line + "\n")
    assert sorted(p.name for p in tmp_path.iterdir()) == before


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
            "splatgl path orbit: error: argument --fps: must be a finite number > 0, got '0' "
            "(see splatgl path orbit --help)")
    refused(capsys, tmp_path, ["render", "--path", "orbit:2", "--fps", "0", "-o", tmp_path / "o.mp4"],
            "splatgl render: error: argument --fps: must be a finite number > 0, got '0' "
            "(see splatgl render --help)")
    out.write_text("{}")
    refused(capsys, tmp_path, ["path", "orbit", DEMO, "--frames", "2", "-o", out],
            f"splatgl: error: {out}: exists; use --force to replace it")
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
