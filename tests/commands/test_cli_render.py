"""`splatgl render` end to end: outputs, camera files, and one-line errors with exit code 2."""

from __future__ import annotations

import json

import numpy as np
import pytest

from splatgl.cameras.camera import Camera
from splatgl.cameras.poses import orbit
from splatgl.cameras.camera_files import load_camera, load_cameras, save_camera
from splatgl.cli import main
from splatgl.commands._common import demo_scene_path
from splatgl.errors import CameraError
from splatgl.formats import load_scene
from splatgl.imagefiles.images import read_image
from splatgl.api import Renderer, default_camera


def test_demo_render_png_matches_api(tmp_path, capsys):
    out = tmp_path / "demo.png"
    assert main(["render", "-o", str(out), "--width", "160", "--height", "90"]) == 0
    assert "wrote" in capsys.readouterr().out
    img = read_image(out)
    assert img.shape == (90, 160, 3)
    scene = load_scene(demo_scene_path())
    with Renderer() as r:
        expected = r.render(scene, default_camera(scene, 160, 90))
    np.testing.assert_allclose(img, np.clip(expected[..., :3], 0, 1), atol=0.5 / 255 + 1e-6)
    assert img.mean() > 0.02  # not an empty frame


def test_exr_has_float_rgba_and_tiff_16_bit(tmp_path):
    exr, tif = tmp_path / "a.exr", tmp_path / "a.tif"
    common = ["--width", "64", "--height", "48", "--background", "0.2,0.3,0.4"]
    assert main(["render", "-o", str(exr), *common]) == 0
    assert main(["render", "-o", str(tif), "--bit-depth", "16", *common]) == 0
    e, t = read_image(exr), read_image(tif)
    assert e.shape == (48, 64, 5) and t.shape == (48, 64, 3)  # R, G, B, A, Z
    np.testing.assert_allclose(t, np.clip(e[..., :3], 0, 1), atol=0.5 / 65535 + 1e-6)
    corner = e[0, 0]
    np.testing.assert_allclose(corner, [0.2, 0.3, 0.4, 0.0, 0.0], atol=1e-6)  # background, A = Z = 0


def test_single_camera_json_round_trip(tmp_path):
    cam = Camera(100, 80, 90.0, 95.0, 49.0, 41.0, orbit([0, 0, 0], 3.0, 20.0, 10.0))
    path = tmp_path / "cam.json"
    save_camera(path, cam)
    back = load_camera(path)
    assert (back.width, back.fx, back.cy) == (100, 90.0, 41.0)
    np.testing.assert_array_equal(back.world_to_camera, cam.world_to_camera)


def test_3dgs_cameras_json(tmp_path):
    c2w = orbit([0, 0, 0], 2.0, 45.0, 0.0)
    w2c = np.linalg.inv(c2w)  # any rigid matrix: treat it as camera-to-world
    entries = [{"id": i, "img_name": f"im{i}", "width": 64, "height": 32,
                "position": w2c[:3, 3].tolist(), "rotation": w2c[:3, :3].tolist(),
                "fx": 50.0, "fy": 51.0} for i in range(3)]
    path = tmp_path / "cameras.json"
    path.write_text(json.dumps(entries))
    cams = load_cameras(path)
    assert len(cams) == 3
    cam = load_camera(path, 2)
    np.testing.assert_allclose(cam.world_to_camera, c2w, atol=1e-12)
    np.testing.assert_allclose(cam.center, w2c[:3, 3], atol=1e-12)
    assert (cam.cx, cam.cy) == (32.0, 16.0)
    with pytest.raises(CameraError, match="index 5 out of range"):
        load_camera(path, 5)
    out = tmp_path / "v.png"
    assert main(["render", "--camera", str(path), "--camera-index", "1", "-o", str(out)]) == 0
    assert read_image(out).shape == (32, 64, 3)


def _run_bad(capsys, argv):
    rc = main(argv)
    err = capsys.readouterr().err
    assert rc == 2, err
    lines = [line for line in err.splitlines() if line.strip()]
    assert len(lines) == 1 and "Traceback" not in err, err
    return lines[0]


def test_bad_inputs_exit_2_with_one_line(tmp_path, capsys):
    out = str(tmp_path / "x.png")
    assert "no such file" in _run_bad(capsys, ["render", str(tmp_path / "missing.ply"), "-o", out])
    bad_json = tmp_path / "bad.json"
    bad_json.write_text("{not json")
    assert "not valid JSON" in _run_bad(capsys, ["render", "--camera", str(bad_json), "-o", out])
    no_fx = tmp_path / "nofx.json"
    no_fx.write_text(json.dumps({"width": 10, "height": 10, "fy": 1, "cx": 1, "cy": 1,
                                 "world_to_camera": np.eye(4).tolist()}))
    assert "'fx'" in _run_bad(capsys, ["render", "--camera", str(no_fx), "-o", out])
    assert "unsupported image format" in _run_bad(capsys, ["render", "-o", str(tmp_path / "x.bmp")])
    assert "--width" in _run_bad(capsys, ["render", "--width", "0", "-o", out])
    assert not list(tmp_path.glob("*.png"))  # nothing half-written


def test_help_texts_explain(capsys):
    with pytest.raises(SystemExit):
        main(["render", "--help"])
    text = capsys.readouterr().out
    for word in ("--camera-index", "--precision", "--background", "examples"):
        assert word in text


@pytest.mark.parametrize("suffix", ["png", "exr"])
def test_background_beyond_float32_is_refused_without_numpy_warnings(tmp_path, capsys, suffix):
    """A background float32 cannot hold overflowed to inf while compositing (NumPy overflow
    and invalid-value warnings, NaN pixels where A = 1): refused in one line, no file."""
    import warnings

    from splatgl.errors import SplatglError
    from splatgl.scene.settings import RenderSettings

    out = tmp_path / f"x.{suffix}"
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert main(["render", "--width", "16", "--height", "12", "--background", "1e308,0,0",
                     "-o", str(out)]) == 2
    assert capsys.readouterr().err == ("splatgl: error: --background 1e+308,0,0: each of R,G,B "
                                       "must be a number from 0 to 3.403e+38 (what a float32 "
                                       "image holds)\n")
    assert not out.exists()
    with pytest.raises(SplatglError, match="each of R,G,B"):
        RenderSettings(background=(0.0, float("nan"), 0.0))
    assert RenderSettings(background=(3e38, 0, 1)).background == (3e38, 0.0, 1.0)
