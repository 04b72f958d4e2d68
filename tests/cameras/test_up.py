"""The default camera's up direction: --up, the training cameras' average, else -y (COLMAP)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from splatgl.cameras.camera import Camera
from splatgl.cameras.poses import look_at
from splatgl.cameras.up import average_up, cameras_beside, resolve_up
from splatgl.cli import main
from splatgl.imagefiles.images import read_image


def orbit_cameras(up, n=6, elevation=0.3):
    """3DGS cameras.json entries circling the origin with ``up`` up (camera-to-world rotation)."""
    up = np.asarray(up, float)
    a = np.cross(up, [1.0, 0.0, 0.0] if abs(up[0]) < 0.9 else [0.0, 1.0, 0.0])
    a /= np.linalg.norm(a)
    b = np.cross(up, a)
    entries = []
    for i in range(n):
        t = 2 * np.pi * i / n
        eye = 3.0 * (np.cos(t) * a + np.sin(t) * b) + elevation * up
        w2c = look_at(eye, np.zeros(3), up)
        entries.append({"id": i, "img_name": f"{i:03d}", "width": 64, "height": 48,
                        "position": eye.tolist(), "rotation": w2c[:3, :3].T.tolist(),
                        "fx": 60.0, "fy": 60.0})
    return entries


def test_average_up_of_cameras_around_an_axis():
    for axis in ([0, 0, 1.0], [0, -1.0, 0], [0, 0.6, 0.8]):
        cams = [Camera(64, 48, 60, 60, 32, 24, look_at(e["position"], [0, 0, 0], axis))
                for e in orbit_cameras(axis)]
        np.testing.assert_allclose(average_up(cams), np.asarray(axis) / np.linalg.norm(axis), atol=1e-12)
    assert average_up([]) is None


def test_cameras_json_is_found_where_3dgs_training_writes_it(tmp_path):
    scene = tmp_path / "out" / "point_cloud" / "iteration_30000" / "point_cloud.ply"
    scene.parent.mkdir(parents=True)
    scene.write_bytes(b"")
    assert cameras_beside(scene) is None
    (tmp_path / "out" / "cameras.json").write_text(json.dumps(orbit_cameras([0, 0, 1.0])))
    assert cameras_beside(scene) == tmp_path / "out" / "cameras.json"
    up, why = resolve_up(None, scene)
    np.testing.assert_allclose(up, [0, 0, 1], atol=1e-12)
    assert why == f"the average up of {tmp_path / 'out' / 'cameras.json'}"
    assert resolve_up("-z", scene)[1] == "--up -z"
    assert resolve_up(None, tmp_path / "elsewhere.ply")[1] == "-y (COLMAP convention)"


def test_default_view_follows_the_cameras_beside_the_scene(tmp_path, shared_scenes, capsys):
    """The donut is z-up: from below with the -y default, upright with cameras beside it."""
    scene = tmp_path / "donut.ply"
    scene.symlink_to(shared_scenes / "ply" / "donut_sh0.ply")
    size = ["--width", "64", "--height", "48"]
    assert main(["render", str(scene), *size, "-o", str(tmp_path / "plus_z.png"), "--up", "+z"]) == 0
    assert main(["render", str(scene), *size, "-o", str(tmp_path / "minus_y.png")]) == 0
    (tmp_path / "cameras.json").write_text(json.dumps(orbit_cameras([0, 0, 1.0])))
    assert main(["render", str(scene), *size, "-o", str(tmp_path / "auto.png")]) == 0
    plus_z, minus_y, auto = (read_image(tmp_path / f"{n}.png") for n in ("plus_z", "minus_y", "auto"))
    np.testing.assert_array_equal(auto, plus_z)
    assert np.abs(minus_y - plus_z).mean() > 0.02  # a different view, not a near copy


def test_up_is_explained_in_help(capsys):
    with pytest.raises(SystemExit):
        main(["render", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert "average up of the training cameras" in text and "COLMAP" in text
