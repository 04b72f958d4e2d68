"""Camera files: every bad pose or value gives one line naming the file's own field (exit 2)."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from splatgl.cameras.poses import check_rigid_pose, look_at, rigid_pose_problem
from splatgl.cameras.camera_files import load_camera, load_cameras
from splatgl.constants import RIGID_POSE_TOLERANCE
from splatgl.errors import CameraError

POSE = look_at([1.0, -2.0, 3.0], [0.0, 0.0, 0.0])


def single(tmp_path, w2c, **extra):
    obj = {"width": 64, "height": 48, "fx": 50.0, "fy": 50.0, "cx": 32.0, "cy": 24.0,
           "world_to_camera": np.asarray(w2c).tolist(), **extra}
    path = tmp_path / "cam.json"
    path.write_text(json.dumps(obj))
    return path


def three_dgs(tmp_path, rotation, position=(0.0, 0.0, -3.0), n=2):
    entry = {"id": 0, "img_name": "a", "width": 64, "height": 48, "fx": 50.0, "fy": 50.0,
             "position": list(position), "rotation": np.asarray(rotation).tolist()}
    path = tmp_path / "cameras.json"
    path.write_text(json.dumps([dict(entry, id=i) for i in range(n)]))
    return path


def pose_with_rotation(r: np.ndarray) -> np.ndarray:
    m = POSE.copy()
    m[:3, :3] = r @ POSE[:3, :3]
    return m


# (3x3 factor applied to a valid rotation, the phrase every loader must print)
BAD_ROTATIONS = [
    (np.diag([1.0, 1.0, -1.0]), "is mirrored (determinant -1, not +1): not a rotation"),
    (2.0 * np.eye(3), "is scaled (its rotation rows have lengths 2, 2, 2, not 1): not a rigid transform"),
    (np.diag([1.0, 1.5, 1.0]), "is scaled (its rotation rows have lengths 1, 1.5, 1, not 1): not a rigid transform"),
    (np.array([[1.0, 0.0, 0.0], [0.6, 0.8, 0.0], [0.0, 0.0, 1.0]]),
     "is sheared (its rotation rows are not orthogonal: largest |cos angle| 0.6, tolerance 0.0001): "
     "not a rigid transform"),
    (np.zeros((3, 3)), "is singular (determinant 0): not a rotation"),
]


@pytest.mark.parametrize("factor, phrase", BAD_ROTATIONS)
def test_same_message_for_single_camera_and_3dgs_list(tmp_path, factor, phrase):
    # A factor applied on the left in camera space: for the 3DGS (camera-to-world) rotation its
    # transpose on the right gives the same rows' lengths, angles and determinant.
    path = single(tmp_path, pose_with_rotation(factor))
    with pytest.raises(CameraError) as info:
        load_camera(path)
    assert str(info.value) == f"{path}: field 'world_to_camera' {phrase}"
    path3 = three_dgs(tmp_path, factor)
    with pytest.raises(CameraError) as info:
        load_cameras(path3)
    assert str(info.value) == f"{path3}: camera 0: field 'rotation' {phrase}"


def test_rigid_within_tolerance_is_accepted_and_beyond_is_not():
    # A rotation rounded to 6 decimals (as some writers store it) is within the tolerance.
    assert rigid_pose_problem(np.round(POSE, 6)) is None
    nudged = POSE.copy()
    nudged[0, 0] += 3 * RIGID_POSE_TOLERANCE
    assert rigid_pose_problem(nudged) is not None
    assert check_rigid_pose(POSE, "x").dtype == np.float64


@pytest.mark.parametrize("value, shown", [(math.nan, "NaN"), (math.inf, "Inf")])
def test_non_finite_pose_names_the_entry(tmp_path, value, shown):
    m = POSE.copy()
    m[1, 2] = value
    path = tmp_path / "cam.json"
    path.write_text(json.dumps({"width": 64, "height": 48, "fx": 50, "fy": 50, "cx": 32, "cy": 24,
                                "world_to_camera": m.tolist()}))
    with pytest.raises(CameraError) as info:
        load_camera(path)
    assert str(info.value) == f"{path}: field 'world_to_camera' holds {shown} at row 1, column 2"


def test_last_row_and_shape_are_named(tmp_path):
    m = POSE.copy()
    m[3, 3] = 2.0
    path = single(tmp_path, m)
    with pytest.raises(CameraError) as info:
        load_camera(path)
    assert str(info.value) == (f"{path}: field 'world_to_camera' must have (0, 0, 0, 1) as its "
                               "last row, got [0.0, 0.0, 0.0, 2.0]")
    path = single(tmp_path, POSE[:3])
    with pytest.raises(CameraError) as info:
        load_camera(path)
    assert str(info.value) == f"{path}: field 'world_to_camera' must be a 4x4 array, got shape (3, 4)"


@pytest.mark.parametrize("position, message", [
    ([0.0, math.nan, 1.0], "field 'position' holds NaN at entry 1"),
    ([0.0, 1.0], "field 'position' must be 3 numbers, got shape (2,)"),
    (["a", 1, 2], "field 'position' must be 3 numbers"),
])
def test_3dgs_position_is_named_as_in_the_file(tmp_path, position, message):
    path = three_dgs(tmp_path, np.eye(3), position=position)
    with pytest.raises(CameraError) as info:
        load_cameras(path)
    assert str(info.value) == f"{path}: camera 0: {message}"


@pytest.mark.parametrize("name, obj, where, field", [
    ("transforms.json", lambda m: {"w": 10, "h": 10, "fl_x": 5.0, "frames": [{"transform_matrix": m}]},
     "frame 0: ", "transform_matrix"),
    ("camera_path.json", lambda m: {"camera_type": "perspective", "render_width": 8, "render_height": 8,
                                    "camera_path": [{"camera_to_world": sum(m, []), "fov": 50}]},
     "camera_path[0]: ", "camera_to_world"),
])
def test_a_non_finite_pose_entry_is_named_in_every_source(tmp_path, name, obj, where, field):
    """A NaN in a transforms.json or camera_path.json pose said "got shape (4, 4)"."""
    import splatgl
    m = np.eye(4).tolist()
    m[1][2] = math.inf
    path = tmp_path / name
    path.write_text(json.dumps(obj(m)))
    with pytest.raises(CameraError) as info:
        splatgl.load_cameras(path)
    assert str(info.value) == f"{path}: {where}field '{field}' holds Inf at row 1, column 2"


def test_api_camera_names_the_non_finite_entry():
    from splatgl.cameras.camera import Camera
    m = np.eye(4)
    m[0, 3] = math.nan
    with pytest.raises(CameraError, match=r"^world_to_camera must be finite; it holds NaN at row 0, "
                                          r"column 3$"):
        Camera(8, 8, 5.0, 5.0, 4.0, 4.0, m)


def test_a_repeated_key_is_one_line_naming_file_and_key(tmp_path, capsys):
    """Issue 38: a camera file giving "fx" twice rendered with the last, without a word."""
    from splatgl.cli import main

    path = single(tmp_path, POSE)
    path.write_text(path.read_text().replace('"fx": 50.0', '"fx": 50.0, "fx": 500.0'))
    rc = main(["render", "--camera", str(path), "-o", str(tmp_path / "x.png")])
    out, err = capsys.readouterr()
    assert (rc, out) == (2, "")
    assert err == (f"splatgl: error: {path}: key 'fx' given twice in one object (JSON keeps only "
                   "the last)\n")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["cam.json"]


@pytest.mark.parametrize("extra, message", [
    ({"projection": "perspective", "distortion": [0.1, 0.0, 0.0, 0.0]},
     "field 'distortion' would be ignored: \"projection\": \"perspective\" does not read it; use "
     "\"projection\": \"opencv\" for OpenCV's distCoeffs (k1 k2 p1 p2 [k3 [k4 k5 k6]]) or "
     "\"fisheye\" for its k1 k2 k3 k4, or remove the field"),
    ({"distortion": [0.1, 0.0, 0.0, 0.0, 0.02]},
     "field 'distortion' would be ignored: the default projection \"perspective\" does not read "
     "it; use \"projection\": \"opencv\" for OpenCV's distCoeffs (k1 k2 p1 p2 [k3 [k4 k5 k6]]) or "
     "\"fisheye\" for its k1 k2 k3 k4, or remove the field"),
    ({"projection": "orthographic", "ods_eye": 0.03},
     "field 'ods_eye' would be ignored: \"projection\": \"orthographic\" does not read it; use "
     "\"projection\": \"equirectangular\", or remove the field"),
    ({"projection": "opencv", "distortion": "0.1 0 0 0"},
     "field 'distortion' must be a list of 4, 5 or 8 numbers (OpenCV's k1 k2 p1 p2 [k3 [k4 k5 "
     "k6]]; 12 or 14 with s1..s4, tauX, tauY 0), got '0.1 0 0 0'"),
    ({"projection": "opencv", "distortion": [0.1] * 8 + [0.0, 0.2, 0.0, 0.3]},
     "field 'distortion': OpenCV's thin-prism and tilted-sensor terms (s2, s4 here) are not "
     "supported; the opencv camera takes k1 k2 p1 p2 [k3 [k4 k5 k6]] (the rest of its 12 numbers "
     "must be 0)"),
    ({"projection": "fisheye", "distortion": [0.1, 0.0, 0.0]},
     "field 'distortion' must be a list of 4 numbers (OpenCV's fisheye k1 k2 k3 k4), got 3"),
])
def test_distortion_the_projection_does_not_take_is_refused(tmp_path, extra, message):
    """Issue 38: a perspective camera with a distortion list rendered undistorted without a word;
    a distortion that was not a list was said to need "8 numbers"."""
    path = single(tmp_path, POSE, **extra)
    with pytest.raises(CameraError) as info:
        load_camera(path)
    assert str(info.value) == f"{path}: {message}"


def test_zero_distortion_and_opencv_14_coefficients_with_zero_extras_are_read(tmp_path):
    assert load_camera(single(tmp_path, POSE, distortion=[0, 0, 0, 0])).model.name == "perspective"
    k = [-0.1, 0.01, 0.001, 0.002, 0.003, 0.0, 0.0, 0.004]
    cam = load_camera(single(tmp_path, POSE, projection="opencv", distortion=k + [0.0] * 6))
    assert cam.model.coefficients == tuple(k)
