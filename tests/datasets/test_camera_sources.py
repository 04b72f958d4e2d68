"""Camera sources: the real garden cameras converted into every format load back as the same
cameras; per format, a file written by hand in that format's axis convention puts a known
world point on a known pixel (rendered as one small splat); bad files fail in one line."""

from __future__ import annotations

import json
import struct
import warnings

import numpy as np
import pytest

import splatgl
from helpers import scene_with_colors, shared_file
from splatgl.cameras.camera import Camera
from splatgl.datasets import colmap, load_source, load_views, nerf, select_indices
from splatgl.datasets.gs_cameras import gs_cameras_json
from splatgl.datasets.nerfstudio_path import camera_path_json
from splatgl.datasets.named_camera import NamedCamera
from splatgl.errors import CameraError
from splatgl.paths import path_json


@pytest.fixture(scope="module")
def garden(shared_scenes):
    data = np.load(shared_file(shared_scenes, "cameras/garden_cameras_points.npz"))
    w, h = int(data["width"]), int(data["height"])
    return [NamedCamera(f"DSC{i:05d}.JPG", Camera(w, h, k[0, 0], k[1, 1], k[0, 2], k[1, 2], v.astype(np.float64)))
            for i, (k, v) in enumerate(zip(data["Ks"], data["viewmats"]))]


def _close(a: Camera, b: Camera, pose_tol: float, intrinsics=("fx", "fy", "cx", "cy")) -> None:
    assert (a.width, a.height) == (b.width, b.height)
    for name in intrinsics:
        assert getattr(a, name) == pytest.approx(getattr(b, name), rel=1e-9), name
    np.testing.assert_allclose(a.world_to_camera, b.world_to_camera, rtol=0, atol=pose_tol)


@pytest.mark.parametrize("binary", [True, False])
def test_garden_as_colmap_model(garden, tmp_path, binary):
    colmap.write_colmap(tmp_path / "sparse" / "0", garden, binary=binary)
    views = load_views(tmp_path)  # a dataset folder: finds sparse/0
    assert [v.name for v in views] == [v.name for v in garden]
    for got, want in zip(views, garden):
        # the float32 garden rotations are orthonormal to ~1e-7; a quaternion stores the nearest
        # rotation, so the round trip moves entries by that much, no more
        _close(got.camera, want.camera, 1e-7)
    ext = ".bin" if binary else ".txt"
    assert len(splatgl.load_cameras(tmp_path / "sparse" / "0" / f"images{ext}")) == 3


def test_garden_as_transforms_json(garden, tmp_path):
    (tmp_path / "transforms.json").write_text(json.dumps(nerf.transforms_json(garden)))
    for got, want in zip(load_views(tmp_path), garden):
        _close(got.camera, want.camera, 1e-12)


def test_garden_as_3dgs_cameras_json(garden, tmp_path):
    (tmp_path / "cameras.json").write_text(json.dumps(gs_cameras_json(garden)))
    for got, want in zip(load_views(tmp_path / "cameras.json"), garden):
        _close(got.camera, want.camera, 1e-6, ("fx", "fy"))  # 3DGS centres the principal point
        assert (got.camera.cx, got.camera.cy) == (want.camera.width / 2, want.camera.height / 2)


def test_garden_as_nerfstudio_camera_path(garden, tmp_path):
    cams = [v.camera for v in garden]
    (tmp_path / "camera_path.json").write_text(json.dumps(camera_path_json(cams, fps=24)))
    views, fps = load_source(tmp_path / "camera_path.json")
    assert fps == 24
    for got, want in zip(views, cams):
        _close(got.camera, want, 1e-6, ("fy",))  # a fov: square pixels, centred


def test_garden_as_splatgl_path(garden, tmp_path):
    cams = [v.camera for v in garden]
    (tmp_path / "p.json").write_text(json.dumps(path_json(cams)))
    got = splatgl.load_cameras(tmp_path / "p.json")
    for g, w in zip(got, cams):
        np.testing.assert_array_equal(g.world_to_camera, w.world_to_camera)  # on the keys: exact
        assert g.fy == pytest.approx(w.fy)


# ------------------------------------------------------------------ one test per convention
W, H, F = 96, 64, 80.0


def _hand_written(fmt: str, tmp_path):
    """(source path, world point, expected pixel (u, v)) of a camera written by hand."""
    if fmt == "colmap":  # world-to-camera, OpenCV axes: identity pose looks along +z, y down
        d = tmp_path / "model"
        d.mkdir()
        (d / "cameras.txt").write_text(f"1 SIMPLE_PINHOLE {W} {H} {F} 40 30\n")
        (d / "images.txt").write_text("1 1 0 0 0 0 0 0 1 a.png\n\n")
        return d, (0.1, 0.2, 1.0), (40 + F * 0.1, 30 + F * 0.2)
    if fmt == "colmap_bin":  # the same camera, rotated 90 degrees about +z (q = cos45, 0, 0, sin45)
        d = tmp_path / "model"
        d.mkdir()
        (d / "cameras.bin").write_bytes(struct.pack("<QiiQQdddd", 1, 1, 1, W, H, F, F, 48, 32))
        s = np.sqrt(0.5)
        (d / "images.bin").write_bytes(struct.pack("<Qidddddddi", 1, 1, s, 0, 0, s, 0, 0, 0, 1) + b"a.png\0"
                                       + struct.pack("<Q", 0))
        # R maps world (0.1, 0.2, 1) to camera (-0.2, 0.1, 1)
        return d, (0.1, 0.2, 1.0), (48 - F * 0.2, 32 + F * 0.1)
    if fmt == "transforms":  # camera-to-world, OpenGL axes: identity looks along -z, y up
        obj = {"camera_angle_x": 2 * np.arctan(W / 2 / F), "w": W, "h": H,
               "frames": [{"file_path": "a", "transform_matrix": np.eye(4).tolist()}]}
        (tmp_path / "transforms.json").write_text(json.dumps(obj))
        return tmp_path / "transforms.json", (0.1, 0.2, -1.0), (W / 2 + F * 0.1, H / 2 - F * 0.2)
    if fmt == "3dgs":  # camera-to-world rotation, OpenCV axes, position = centre
        obj = [{"id": 0, "img_name": "a", "width": W, "height": H, "fx": F, "fy": F,
                "position": [0, 0, -2], "rotation": np.eye(3).tolist()}]
        (tmp_path / "cameras.json").write_text(json.dumps(obj))
        return tmp_path / "cameras.json", (0.1, 0.2, 0.0), (W / 2 + F * 0.05, H / 2 + F * 0.1)
    if fmt == "nerfstudio":  # camera_to_world, OpenGL axes, vertical fov in degrees
        fov = float(np.degrees(2 * np.arctan(H / 2 / F)))
        c2w = np.eye(4)
        c2w[:3, 3] = [0, 0, 1]
        obj = {"render_width": W, "render_height": H, "fps": 30, "seconds": 1,
               "camera_path": [{"camera_to_world": c2w.reshape(-1).tolist(), "fov": fov}]}
        (tmp_path / "camera_path.json").write_text(json.dumps(obj))
        return tmp_path / "camera_path.json", (0.1, 0.2, 0.0), (W / 2 + F * 0.1, H / 2 - F * 0.2)
    if fmt == "splatgl":  # look-at with up = world -y: world +x is right, world +y is down
        fov = float(np.degrees(2 * np.arctan(H / 2 / F)))
        obj = {"splatgl_path": 1, "width": W, "height": H, "frames": 1,
               "keyframes": [{"eye": [0, 0, -5], "target": [0, 0, 0], "up": [0, -1, 0], "fov": fov}]}
        (tmp_path / "p.json").write_text(json.dumps(obj))
        return tmp_path / "p.json", (0.1, 0.2, 0.0), (W / 2 + F * 0.02, H / 2 + F * 0.04)
    raise AssertionError(fmt)


@pytest.mark.parametrize("fmt", ["colmap", "colmap_bin", "transforms", "3dgs", "nerfstudio", "splatgl"])
def test_known_point_lands_on_known_pixel(fmt, tmp_path, gl_renderer):
    source, point, (u, v) = _hand_written(fmt, tmp_path)
    (cam,) = splatgl.load_cameras(source)
    depth = (cam.world_to_camera @ [*point, 1.0])[2]
    sigma = 0.8 * depth / cam.fx  # a splat about 0.8 px across
    scene = scene_with_colors([point], [[1, 0, 0, 0]], [[sigma] * 3], [0.9], [[1, 1, 1]])
    alpha = gl_renderer.render(scene, cam)[..., 3].astype(np.float64)
    assert alpha.sum() > 0.5, "the splat is not in view"
    rows, cols = np.mgrid[0:cam.height, 0:cam.width]
    got = ((alpha * (cols + 0.5)).sum() / alpha.sum(), (alpha * (rows + 0.5)).sum() / alpha.sum())
    # pixel centres at (j + 0.5, i + 0.5): the alpha centroid is the projected point within a
    # small fraction of a pixel (the splat is symmetric; only pixel sampling moves it)
    assert got == pytest.approx((u, v), abs=0.1)


# ------------------------------------------------------------------ bad files
def _err(path) -> str:
    with pytest.raises(CameraError) as info:
        splatgl.load_cameras(path)
    return str(info.value)


def test_bad_sources_fail_in_one_line(tmp_path):
    (tmp_path / "x.json").write_text('{"hello": 1}')
    assert "x.json: not a camera source splatgl knows" in _err(tmp_path / "x.json")
    (tmp_path / "empty").mkdir()
    assert "folder holds no camera source" in _err(tmp_path / "empty")
    m = tmp_path / "m"
    m.mkdir()
    (m / "cameras.txt").write_text("1 OPENCV 10 10 5 5 5 5 0.1 0 0 0\n")
    (m / "images.txt").write_text("1 1 0 0 0 0 0 0 1 a.png\n\n")
    (m / "cameras.txt").write_text("1 FOV 10 10 5 5 5 5 0.1\n")
    assert "camera 1: COLMAP model FOV is not one splatgl renders" in _err(m)
    (m / "cameras.txt").write_text("1 PINHOLE 10 10 5 5 5\n")
    assert "line 1: model PINHOLE takes 4 parameters, got 3" in _err(m)
    (m / "cameras.txt").write_text("1 PINHOLE 10 10 5 5 5 5\n")
    (m / "images.txt").write_text("1 1 0 0 0 0 0 0 7 a.png\n\n")
    assert "image 'a.png': camera id 7 is not in" in _err(m)
    (m / "images.txt").write_text("1 0 0 0 0 0 0 0 1 a.png\n\n")
    assert "pose must be finite with a non-zero quaternion" in _err(m)
    t = {"w": 10, "h": 10, "fl_x": 5, "k1": 0.2, "camera_model": "PINHOLE",
         "frames": [{"transform_matrix": np.eye(4).tolist()}]}
    (tmp_path / "t.json").write_text(json.dumps(t))
    assert "field 'k1' = 0.2: lens distortion is not supported" in _err(tmp_path / "t.json")
    t["k1"] = 0
    t["frames"][0]["transform_matrix"] = np.diag([1, 1, -1, 1]).tolist()
    (tmp_path / "t.json").write_text(json.dumps(t))
    assert "frame 0: field 'transform_matrix' is mirrored" in _err(tmp_path / "t.json")
    p = {"camera_type": "fisheye", "render_width": 8, "render_height": 8, "camera_path": []}
    (tmp_path / "cp.json").write_text(json.dumps(p))
    assert "'camera_type' is 'fisheye'; splatgl renders 'perspective' only" in _err(tmp_path / "cp.json")
    (tmp_path / "model_b").mkdir()
    (tmp_path / "model_b" / "cameras.bin").write_bytes(struct.pack("<Q", 1) + b"\0" * 5)
    (tmp_path / "model_b" / "images.bin").write_bytes(struct.pack("<Q", 0))
    assert "cameras.bin: truncated at byte 8" in _err(tmp_path / "model_b")


@pytest.mark.parametrize("line, fx, fy", [
    ("1 SIMPLE_RADIAL 10 8 7 5 4 0", 7, 7), ("1 RADIAL 10 8 7 5 4 0 0", 7, 7),
    ("1 OPENCV 10 8 7 6 5 4 0 0 0 0", 7, 6), ("1 FULL_OPENCV 10 8 7 6 5 4" + " 0" * 8, 7, 6),
])
def test_colmap_models_with_zero_distortion_are_pinholes(tmp_path, line, fx, fy, monkeypatch):
    """SIMPLE_RADIAL and the other distortion models were refused as distorted even at k = 0.
    With distortion they are the opencv camera (tests/cameras/test_opencv_camera.py); without that
    model registered, the pinhole's own reading of the names refuses it as before."""
    from splatgl.cameras import registry
    from splatgl.cameras.pinhole import Pinhole

    (tmp_path / "cameras.txt").write_text(line + "\n")
    (tmp_path / "images.txt").write_text("1 1 0 0 0 0 0 0 1 a.png\n\n")
    cam = splatgl.load_cameras(tmp_path)[0]
    assert (cam.projection, cam.width, cam.height, cam.fx, cam.fy) == ("perspective", 10, 8, fx, fy)
    assert (cam.cx, cam.cy) == (5, 4) and cam.projection == "perspective"
    (tmp_path / "cameras.txt").write_text(line[:-1] + "0.01\n")
    assert splatgl.load_cameras(tmp_path)[0].projection == "opencv"
    monkeypatch.setitem(colmap.COLMAP, line.split()[1], Pinhole)
    with pytest.raises(CameraError, match=r"cameras.txt: camera 1: COLMAP model \w+ has nonzero lens "
                                          r"distortion \([0 ]*0.01\), which splatgl does not render"):
        splatgl.load_cameras(tmp_path)
    assert registry.COLMAP is colmap.COLMAP


@pytest.mark.parametrize("where", ["", "sparse/0"])
def test_half_a_colmap_model_names_what_is_missing(tmp_path, where):
    """A COLMAP folder without images.txt said "no transforms.json" (eval) or "holds no camera
    source"; now it names the model and the missing file."""
    from splatgl.datasets.dataset import load_dataset
    model = tmp_path / where
    model.mkdir(parents=True, exist_ok=True)
    (model / "cameras.txt").write_text("1 PINHOLE 10 10 5 5 5 5\n")
    (model / "points3D.txt").write_text("")
    line = f"{model}: COLMAP model with cameras.txt, points3D.txt but no images.txt"
    assert _err(tmp_path) == line
    with pytest.raises(CameraError) as info:
        load_dataset(tmp_path)
    assert str(info.value) == line


def test_select_ranges():
    assert select_indices("0:12:5", 12) == [0, 5, 10]
    assert select_indices("1,3,-1", 12) == [1, 3, 11]
    assert select_indices("::4,2", 10) == [0, 4, 8, 2]
    for spec, msg in [("12", "index 12 out of range (12 cameras)"), ("a", "'a' is not an index"),
                      ("0:5:0", "'0:5:0' is not an index"), ("5:2", "picks no camera of 12"),
                      ("0:100:5", "'0:100:5': stop 100 out of range (12 cameras)")]:
        with pytest.raises(CameraError, match=msg.replace("(", r"\(").replace(")", r"\)")):
            select_indices(spec, 12)


# ------------------------------------------------------------------ the camera models' file table
def test_file_names_belong_to_the_last_model_claiming_them(monkeypatch):
    """The registry's COLMAP and transforms.json tables come from the models' own name lists;
    a model registered later takes a name over (how a new model replaces the pinhole's
    zero-distortion reading of SIMPLE_RADIAL without touching pinhole.py)."""
    from dataclasses import dataclass
    from splatgl.cameras import registry
    from splatgl.cameras.pinhole import Pinhole

    @dataclass(frozen=True)
    class Taker(Pinhole):
        name = "taker"
        colmap_names = ("SIMPLE_RADIAL", "FOV")
        transforms_names = ("OPENCV",)

    assert "SIMPLE_RADIAL" in Pinhole.colmap_names and "FOV" not in registry.COLMAP
    assert registry.COLMAP["SIMPLE_RADIAL"].name == "opencv"   # registered after the pinhole
    assert registry.COLMAP["OPENCV_FISHEYE"].name == "fisheye"
    monkeypatch.setitem(registry.MODELS, "taker", Taker)
    colmap_table, transforms_table = registry._claims("colmap_names"), registry._claims("transforms_names")
    assert colmap_table["SIMPLE_RADIAL"] is Taker and colmap_table["FOV"] is Taker
    assert colmap_table["PINHOLE"] is Pinhole and transforms_table["OPENCV"] is Taker
    assert list(colmap_table)[:2] == ["SIMPLE_PINHOLE", "PINHOLE"]  # order of first claim


def test_unknown_models_are_refused_naming_the_supported_ones(tmp_path):
    (tmp_path / "cameras.txt").write_text("1 FOV 10 8 7 6 5 4 0.1\n")
    (tmp_path / "images.txt").write_text("1 1 0 0 0 0 0 0 1 a.png\n\n")
    msg = _err(tmp_path)
    assert "camera 1: COLMAP model FOV is not one splatgl renders; undistort the images first " \
           "(supported: SIMPLE_PINHOLE, PINHOLE," in msg and "OPENCV_FISHEYE" in msg
    t = {"w": 10, "h": 10, "fl_x": 5, "camera_model": "EQUIRECTANGULAR",
         "frames": [{"transform_matrix": np.eye(4).tolist()}]}
    (tmp_path / "t.json").write_text(json.dumps(t))
    assert _err(tmp_path / "t.json").endswith(
        "t.json: frame 0: camera_model 'EQUIRECTANGULAR' is not supported (supported: OPENCV, "
        "PINHOLE, SIMPLE_PINHOLE, OPENCV_FISHEYE)")


@pytest.mark.parametrize("binary", [True, False])
def test_colmap_writer_keeps_each_cameras_model(tmp_path, binary):
    """write_colmap wrote every camera as PINHOLE, so a fisheye came back as a pinhole; each
    model now writes its own COLMAP form."""
    pose = np.eye(4)
    pose[:3, 3] = (0.1, -0.2, 0.3)
    views = [NamedCamera("a.png", Camera(40, 30, 20, 22, 19.5, 15.25, pose)),
             NamedCamera("b.png", Camera.fisheye(40, 30, 190.0, pose, (0.05, -0.01, 0.002, -0.0003)))]
    colmap.write_colmap(tmp_path, views, binary=binary)
    got = colmap.load_colmap(tmp_path)
    for g, w in zip(got, views):
        assert g.camera.model == w.camera.model
        _close(g.camera, w.camera, 1e-12)
    line = (tmp_path / "cameras.txt").read_text().splitlines()[2] if not binary else ""
    assert binary or line.startswith("2 OPENCV_FISHEYE 40 30 ")


def test_writers_refuse_models_the_format_cannot_hold(tmp_path):
    views = [NamedCamera("a.png", Camera(40, 30, 20, 20, 20, 15)), NamedCamera("b.png", Camera.equirectangular(40, 20))]
    with pytest.raises(CameraError, match="^COLMAP has no camera model for equirectangular cameras$"):
        colmap.write_colmap(tmp_path / "m", views)
    assert not (tmp_path / "m").exists()  # refused before anything was written
    with pytest.raises(CameraError, match="^transforms.json has no camera model for equirectangular"):
        nerf.transforms_json(views)


def test_transforms_json_keeps_a_fisheye(tmp_path):
    """transforms.json's OPENCV_FISHEYE (nerfstudio's k1..k4 of theta_d) reads as splatgl's
    fisheye; pinholes keep the file's plain OPENCV frames."""
    views = [NamedCamera("a.png", Camera(40, 30, 20, 22, 19.5, 15.25)),
             NamedCamera("b.png", Camera.fisheye(40, 30, 190.0, None, (0.05, -0.01, 0.002, -0.0003)))]
    obj = nerf.transforms_json(views)
    assert "camera_model" not in obj["frames"][0] and obj["frames"][1]["camera_model"] == "OPENCV_FISHEYE"
    assert obj["frames"][1]["k4"] == -0.0003
    (tmp_path / "transforms.json").write_text(json.dumps(obj))
    for g, w in zip(load_views(tmp_path), views):
        assert g.camera.model == w.camera.model
        _close(g.camera, w.camera, 1e-12)


# ------------------------------------------------------------------ repeated keys
def _repeat_first_key(path) -> str:
    """Give the first object of the JSON file at ``path`` its first key twice (the later one
    wins in Python's json); return the key."""
    text = path.read_text()
    at = text.index("{") + 1
    key = text[at:].split('"')[1]  # json.dumps writes {"key": ...
    path.write_text(f'{text[:at]}"{key}": 0, {text[at:]}')
    return key


@pytest.mark.parametrize("fmt", ["transforms", "3dgs", "nerfstudio", "splatgl"])
def test_a_repeated_key_is_refused_naming_file_and_key(fmt, tmp_path):
    """Issue 38: JSON keeps the last of a repeated key without a word."""
    source, _, _ = _hand_written(fmt, tmp_path)
    key = _repeat_first_key(source)
    assert _err(source) == f"{source}: key '{key}' given twice in one object (JSON keeps only the last)"


@pytest.mark.parametrize("name, obj, line", [
    ("p.json", {"splatgl_path": 1, "width": 8, "height": 8, "frames": 1,
                "keyframes": [{"eye": [0, 0, -1e300], "target": [0, 0, 0]}]},
     "keyframes[0]: look_at: eye [0.0, 0.0, -1e+300] and target [0.0, 0.0, 0.0] must lie within "
     "1e+18 of the origin (float32 arithmetic)"),
    ("p.json", {"splatgl_path": 1, "width": 8, "height": 8, "frames": 1,
                "keyframes": [{"eye": [0, 0, -5], "target": [0, 0, 0], "fov": 1e-300}]},
     "keyframes[0]: camera fx must be from 1e-09 to 1e+18 pixels (float32 arithmetic), got 4.58366e+302"),
    ("transforms.json", {"w": 8, "h": 8, "fl_x": 5.0, "frames": [
        {"transform_matrix": [[1, 0, 0, 1e300], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]}]},
     "frame 0: world_to_camera holds -1e+300 at row 0, column 3 (the camera is that far from the "
     "origin); splatgl renders within 1e+18 (float32 arithmetic)"),
])
def test_numbers_beyond_float32_are_one_line_naming_the_entry(tmp_path, name, obj, line):
    """Issue 38: a path key 1e300 away leaked NumPy's "overflow encountered in dot"."""
    path = tmp_path / name
    path.write_text(json.dumps(obj))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert _err(path) == f"{path}: {line}"
