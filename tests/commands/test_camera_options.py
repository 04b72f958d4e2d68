"""A camera file with --width/--height/--projection/--fov (issue 25, item 4 and part of 8).

The rule lives in :func:`splatgl.cameras.registry.adapt_camera` (reached from the API as
``splatgl.load_camera(path, width=..., projection=...)``): the file's own intrinsics scale
keeping its aspect; another projection or a field of view keeps only its pose, at any size.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

import splatgl
from splatgl.cameras.poses import look_at
from splatgl.cli import build_parser, main
from splatgl.commands._common import camera_from_args
from splatgl.errors import CameraError
from splatgl.imagefiles.images import read_image

POSE = look_at([0.0, -0.5, -3.0], [0.0, 0.0, 0.0])


@pytest.fixture
def cam_file(tmp_path):
    path = tmp_path / "cam.json"
    path.write_text(json.dumps({"width": 64, "height": 48, "fx": 60.0, "fy": 60.0, "cx": 30.0,
                                "cy": 24.0, "world_to_camera": POSE.tolist()}))
    return path


@pytest.mark.parametrize("kwargs, size, projection", [
    ({"projection": "equirectangular", "width": 128, "height": 48}, (128, 48), "equirectangular"),
    ({"projection": "equirectangular"}, (96, 48), "equirectangular"),           # 2:1, file's height
    ({"projection": "equirectangular", "width": 100}, (100, 50), "equirectangular"),
    ({"projection": "equirectangular", "height": 30}, (60, 30), "equirectangular"),
    ({"projection": "fisheye", "width": 50, "height": 50}, (50, 50), "fisheye"),
    ({"projection": "fisheye"}, (64, 48), "fisheye"),                           # the file's size
    ({"projection": "fisheye", "height": 96}, (128, 96), "fisheye"),            # the file's aspect
    ({"fov_degrees": 30.0, "width": 40, "height": 40}, (40, 40), "perspective"),
])
def test_new_intrinsics_keep_only_the_pose_at_any_size(cam_file, kwargs, size, projection):
    cam = splatgl.load_camera(cam_file, **kwargs)
    assert (cam.width, cam.height) == size and cam.projection == projection
    np.testing.assert_array_equal(cam.world_to_camera, POSE)
    if projection == "equirectangular":   # a full panorama whatever the size
        assert cam.fx == pytest.approx(size[0] / (2 * np.pi)) and cam.fy == pytest.approx(size[1] / np.pi)
    if projection == "perspective":
        assert cam.fy == pytest.approx(20 / np.tan(np.radians(15)))


def test_own_intrinsics_scale_and_refuse_another_aspect(cam_file):
    cam = splatgl.load_camera(cam_file, width=32)
    assert (cam.width, cam.height, cam.fx, cam.cx) == (32, 24, 30.0, 15.0)
    with pytest.raises(CameraError, match=r"--width 100 --height 100 would stretch .*cam.json's "
                                          r"64x48 view"):
        splatgl.load_camera(cam_file, width=100, height=100)
    with pytest.raises(CameraError, match=r"--fov 90 does not apply: an equirectangular panorama "
                                          r"always spans 360 x 180 degrees"):
        splatgl.load_camera(cam_file, projection="equirectangular", fov_degrees=90)
    with pytest.raises(CameraError, match="--fov 40 does not apply: an orthographic camera"):
        splatgl.load_camera(cam_file, projection="orthographic", fov_degrees=40)


def test_cli_render_takes_the_pose_and_the_options_size(cam_file, tmp_path, capsys):
    out = tmp_path / "pano.png"
    assert main(["render", "--camera", str(cam_file), "--projection", "equirectangular",
                 "--width", "128", "--height", "48", "-o", str(out)]) == 0
    assert "wrote" in capsys.readouterr().out and read_image(out).shape[:2] == (48, 128)
    assert main(["render", "--camera", str(cam_file), "--projection", "equirectangular",
                 "-o", str(out), "--force"]) == 0
    assert read_image(out).shape[:2] == (48, 96)
    assert main(["render", "--camera", str(cam_file), "--projection", "fisheye", "--fov", "200",
                 "--width", "40", "--height", "40", "-o", str(out), "--force"]) == 0
    assert read_image(out).shape[:2] == (40, 40)


@pytest.mark.parametrize("command", ["view", "compare", "render"])
def test_every_command_adapts_the_file_the_same_way(cam_file, command):
    argv = [command, "--camera", str(cam_file), "--projection", "equirectangular", "--width",
            "128", "--height", "48"] + (["-o", "x.png"] if command == "render" else [])
    args = build_parser().parse_args(argv)
    cam = camera_from_args(args, None)
    assert (cam.width, cam.height, cam.projection) == (128, 48, "equirectangular")


@pytest.mark.parametrize("extra, line", [
    (["--fov", "90", "--projection", "equirectangular"],
     "--fov 90 does not apply: an equirectangular panorama always spans 360 x 180 degrees"),
    (["--orthographic"], "--orthographic zooms the default camera to frame the scene; {cam} "
                         "brings its own camera (--projection orthographic keeps its fx, fy as "
                         "pixels per world unit)"),
    (["--distance", "2"], "--distance places the default camera; {cam} brings its own pose"),
])
def test_camera_file_refuses_options_it_would_ignore(cam_file, tmp_path, capsys, extra, line):
    rc = main(["render", "--camera", str(cam_file), *extra, "-o", str(tmp_path / "x.png")])
    assert (rc, capsys.readouterr().err) == (2, "splatgl: error: " + line.format(cam=cam_file) + "\n")


@pytest.mark.parametrize("extra, line", [
    (["--orthographic", "--projection", "fisheye"],
     "--orthographic contradicts --projection fisheye (--orthographic is --projection "
     "orthographic); give one of them"),
    (["--orthographic", "--fov", "40"],
     "--fov 40 does not apply: an orthographic camera has no field of view (its scale is pixels "
     "per world unit)"),
    (["--projection", "equirectangular", "--fov", "120"],
     "--fov 120 does not apply: an equirectangular panorama always spans 360 x 180 degrees"),
])
def test_default_camera_refuses_contradicting_options(tmp_path, capsys, extra, line):
    rc = main(["render", *extra, "-o", str(tmp_path / "x.png")])
    assert (rc, capsys.readouterr().err) == (2, "splatgl: error: " + line + "\n")
    assert not (tmp_path / "x.png").exists()


def test_default_panorama_is_two_to_one(tmp_path, capsys):
    out = tmp_path / "p.png"
    assert main(["render", "--projection", "equirectangular", "--height", "24", "-o", str(out)]) == 0
    assert read_image(out).shape[:2] == (24, 48)


def test_fov_with_a_camera_file_sets_the_field_of_view(cam_file, tmp_path, capsys):
    """--fov with --camera was dropped without a word; now it replaces the intrinsics."""
    args = build_parser().parse_args(["render", "--camera", str(cam_file), "--fov", "90", "-o", "x.png"])
    cam = camera_from_args(args, None)
    assert (cam.width, cam.height) == (64, 48) and cam.fy == pytest.approx(24.0)
    np.testing.assert_array_equal(cam.world_to_camera, POSE)


def test_compare_refuses_stereo_it_would_ignore(capsys):
    rc = main(["compare", "--stereo", "0.1", "--width", "32", "--height", "24"])
    assert (rc, capsys.readouterr().err) == (2, "splatgl: error: --stereo renders with splatgl "
                                                "render or view; compare measures one view\n")
