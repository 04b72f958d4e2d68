"""Camera paths: keyframe interpolation (C1 positions, unit quaternions, exact keys, linear
fov), the path file's rules and errors, and the generators on the real garden cameras."""

from __future__ import annotations

import json

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from helpers import shared_file
from splatgl.cameras.camera import Camera
from splatgl.cameras.poses import look_at
from splatgl.datasets.sources import load_source
from splatgl.errors import CameraError
from splatgl.paths import ellipse, focus_point, interpolate, orbit, spiral
from splatgl.scene.quaternion import quat_to_rotmat, rotmat_to_quat
from splatgl.paths.spline import sample_poses
from splatgl.scene.splats import Scene


def _keys(n: int, seed: int = 0):
    rng = np.random.default_rng(seed)
    c2w = []
    for _ in range(n):
        eye = rng.normal(0, 3, 3)
        c2w.append(np.linalg.inv(look_at(eye, rng.normal(0, 0.3, 3))))
    return np.array(c2w), rng.uniform(30, 70, n)


@pytest.mark.parametrize("rotation", ["squad", "slerp"])
@pytest.mark.parametrize("loop", [False, True])
def test_spline_passes_keys_exactly_and_is_c1(rotation, loop):
    c2w, fovs = _keys(5)
    times = np.array([0.0, 1.0, 2.5, 3.0, 4.5]) if not loop else np.arange(5.0)
    mats, f = sample_poses(c2w, fovs, times, times, loop, rotation)
    np.testing.assert_array_equal(mats, c2w)
    np.testing.assert_array_equal(f, fovs)
    eps = 1e-6
    for t in times[1:-1]:
        (a, b, c), fa = sample_poses(c2w, fovs, times, [t - eps, t, t + eps], loop, rotation)
        left, right = (b[:3, 3] - a[:3, 3]) / eps, (c[:3, 3] - b[:3, 3]) / eps
        # C1: the velocity is continuous across the key (finite differences agree to O(eps))
        assert np.abs(left - right).max() < 1e-4 * max(1.0, np.abs(left).max())
        if rotation == "squad":  # squad is C1 in rotation too (uniform keys)
            if loop or np.allclose(np.diff(times), 1.0):
                assert np.abs((b[:3, :3] - a[:3, :3]) - (c[:3, :3] - b[:3, :3])).max() < 1e-9


def test_fov_is_linear_between_keys():
    c2w, _ = _keys(2)
    _, f = sample_poses(c2w, np.array([30.0, 60.0]), np.array([0.0, 2.0]), np.array([0.5, 1.0, 1.5]))
    np.testing.assert_allclose(f, [37.5, 45.0, 52.5])


@settings(max_examples=40)
@given(st.integers(0, 10_000), st.floats(0.0, 4.0))
def test_interpolated_rotations_are_proper(seed, t):
    c2w, fovs = _keys(4, seed)
    (m,), _ = sample_poses(c2w, fovs, np.arange(4.0), [t])
    r = m[:3, :3]
    assert np.abs(r @ r.T - np.eye(3)).max() < 1e-12 and np.linalg.det(r) == pytest.approx(1.0)


def test_quaternion_round_trip():
    rng = np.random.default_rng(1)
    for _ in range(50):
        q = rng.normal(size=4)
        q /= np.linalg.norm(q)
        q = q if q[0] >= 0 else -q
        np.testing.assert_allclose(rotmat_to_quat(quat_to_rotmat(q)), q, atol=1e-12)


def _path_file(tmp_path, **kw):
    obj = {"splatgl_path": 1, "width": 64, "height": 48, "frames": 5,
           "keyframes": [{"eye": [0, 0, -5], "target": [0, 0, 0]}, {"eye": [5, 0, 0], "target": [0, 0, 0], "fov": 40},
                         {"world_to_camera": look_at([0, 0, 5], [0, 0, 0]).tolist(), "fov": 30}]}
    obj.update(kw)
    obj = {k: v for k, v in obj.items() if v is not None}
    (tmp_path / "p.json").write_text(json.dumps(obj))
    return tmp_path / "p.json"


def test_path_file_frames_fps_and_loop(tmp_path):
    views, _ = load_source(_path_file(tmp_path))
    cams = [v.camera for v in views]
    assert len(cams) == 5 and (cams[0].width, cams[0].height) == (64, 48)
    np.testing.assert_allclose(cams[0].center, [0, 0, -5], atol=1e-12)
    np.testing.assert_allclose(cams[2].center, [5, 0, 0], atol=1e-12)
    np.testing.assert_array_equal(cams[4].world_to_camera, look_at([0, 0, 5], [0, 0, 0]))
    views, fps = load_source(_path_file(tmp_path, frames=None, fps=10, seconds=2))
    assert len(views) == 20 and fps == 10
    with_times = _path_file(tmp_path, keyframes=[{"eye": [0, 0, -5], "target": [0, 0, 0], "time": 0},
                                                  {"eye": [5, 0, 0], "target": [0, 0, 0], "time": 3}])
    assert len(load_source(with_times)[0]) == 5
    loop, _ = load_source(_path_file(tmp_path, loop=True, frames=6))
    assert len(loop) == 6  # one cycle; frame 6 would repeat frame 0
    np.testing.assert_allclose(loop[2].camera.center, [5, 0, 0], atol=1e-12)  # 3 keys over 6 frames
    np.testing.assert_allclose(loop[4].camera.center, [0, 0, 5], atol=1e-12)


@pytest.mark.parametrize("change, message", [
    ({"splatgl_path": 2}, "field 'splatgl_path' must be 1, got 2"),
    ({"frames": None}, "needs 'frames', or 'fps' and 'seconds'"),
    ({"frames": 2.5}, "field 'frames' must be a whole number, got 2.5"),
    ({"keyframes": []}, "field 'keyframes' must be a non-empty list"),
    ({"keyframes": [{"eye": [0, 0, 1]}]}, "keyframes[0]: missing field 'target'"),
    ({"keyframes": [{"eye": [1, 1, 1], "target": [1, 1, 1]}]}, "keyframes[0]: 'eye' and 'target' coincide"),
    ({"keyframes": [{"world_to_camera": np.diag([1, 1, -1, 1]).tolist()}]}, "field 'world_to_camera' is mirrored"),
    ({"keyframes": [{"eye": [0, 0, 1], "target": [0, 0, 0], "fov": 190}]}, "field 'fov' must be in (0, 180) degrees"),
    ({"keyframes": [{"eye": [0, 0, 1], "target": [0, 0, 0], "time": 1}, {"eye": [0, 0, 2], "target": [0, 0, 0], "time": 1}]},
     "keyframe times must increase strictly"),
    ({"rotation": "spline"}, "field 'rotation' must be 'squad' or 'slerp'"),
    ({"projection": "lens"}, "field 'projection' must be one of 'perspective', 'orthographic'"),
    ({"projection": "equirectangular", "projection_fov": 90},
     "field 'projection_fov' does not apply to projection 'equirectangular': an equirectangular "
     "panorama always spans 360 x 180 degrees"),
    ({"projection_fov": 90}, "field 'projection_fov' does not apply to projection 'perspective'"),
    ({"projection": "fisheye", "projection_fov": 400},
     "field 'projection_fov' of a fisheye must be in (0, 360] degrees, got 400"),
])
def test_path_file_errors(tmp_path, change, message):
    path = _path_file(tmp_path)
    obj = json.loads(path.read_text())
    for k, v in change.items():
        if v is None:
            obj.pop(k)
        else:
            obj[k] = v
    path.write_text(json.dumps(obj))
    with pytest.raises(CameraError) as info:
        load_source(path)
    assert str(info.value).startswith(f"{path}: ") and message in str(info.value)


def test_path_file_projection_reprojects_every_frame(tmp_path):
    """A path's "projection" (the viewer's K in a lens view writes it): every frame is that
    model at the frame's pose, as --projection/--fov re-project the perspective keys."""
    from splatgl.cameras.registry import retarget

    plain = [v.camera for v in load_source(_path_file(tmp_path))[0]]
    for projection, fov, model in (("fisheye", 200.0, "Fisheye"),
                                   ("equirectangular", None, "Equirectangular"),
                                   ("orthographic", None, "Orthographic")):
        extra = {"projection": projection, **({"projection_fov": fov} if fov else {})}
        cams = [v.camera for v in load_source(_path_file(tmp_path, **extra))[0]]
        assert [type(c.model).__name__ for c in cams] == [model] * len(plain)
        for c, p in zip(cams, plain):
            want = retarget(p, projection, fov)
            np.testing.assert_array_equal(c.world_to_camera, p.world_to_camera)
            assert (c.fx, c.fy, c.cx, c.cy, c.model) == (want.fx, want.fy, want.cx, want.cy, want.model)
    same = [v.camera for v in load_source(_path_file(tmp_path, projection="perspective"))[0]]
    assert [c.fx for c in same] == [c.fx for c in plain]


def test_orbit_circles_the_robust_centre():
    rng = np.random.default_rng(0)
    means = rng.normal(0, 1, (500, 3)) + [1, 2, 3]
    scene = Scene.from_activated(means, np.tile([1.0, 0, 0, 0], (500, 1)), np.full((500, 3), 0.01),
                                 np.full(500, 0.5), np.zeros((500, 1, 3)))
    lo, hi = scene.robust_bounds
    centre = 0.5 * (lo + hi)
    cams = orbit(scene, 12, 64, 48, 50.0, 20.0, radius=7.0)
    d = np.array([c.center - centre for c in cams])
    np.testing.assert_allclose(np.linalg.norm(d, axis=1), 7.0)
    np.testing.assert_allclose(-d[:, 1] / 7.0, np.sin(np.radians(20.0)))  # elevation towards -y
    for c in cams:  # looks at the centre: it projects to the image centre
        p = c.world_to_camera @ [*centre, 1]
        assert (c.fx * p[0] / p[2] + c.cx, c.fy * p[1] / p[2] + c.cy) == pytest.approx((32, 24))
    from splatgl.api import default_camera
    np.testing.assert_allclose(orbit(scene, 4, 64, 48)[0].world_to_camera, default_camera(scene, 64, 48).world_to_camera, atol=1e-12)


@pytest.fixture(scope="module")
def garden_cams(shared_scenes):
    data = np.load(shared_file(shared_scenes, "cameras/garden_cameras_points.npz"))
    return [Camera(int(data["width"]), int(data["height"]), k[0, 0], k[1, 1], k[0, 2], k[1, 2], v.astype(float))
            for k, v in zip(data["Ks"], data["viewmats"])]


def test_spiral_and_ellipse_look_at_the_garden_focus(garden_cams):
    target = focus_point(garden_cams)
    # the garden cameras look at the table: their axes pass near the focus point
    for c in garden_cams:
        p = c.world_to_camera @ [*target, 1]
        assert p[2] > 0 and np.hypot(p[0], p[1]) / p[2] < 0.15
    centres = np.array([c.center for c in garden_cams])
    spread = np.linalg.norm(centres - centres.mean(0), axis=1).max()
    for cams in (spiral(garden_cams, 30), ellipse(garden_cams, 30)):
        assert len(cams) == 30
        for c in cams:
            p = c.world_to_camera @ [*target, 1]
            assert p[2] > 0 and abs(p[0]) < 1e-9 and abs(p[1]) < 1e-9
            # image up stays near the cameras' mean up (no roll flips)
            up = -np.mean([g.rotation[1] for g in garden_cams], 0)
            assert -c.rotation[1] @ up / np.linalg.norm(up) > 0.9
        eyes = np.array([c.center for c in cams])
        assert np.linalg.norm(eyes - centres.mean(0), axis=1).max() < 3 * spread + np.linalg.norm(target - centres.mean(0))


def test_interpolate_between_garden_cameras(garden_cams):
    cams = interpolate(garden_cams, 9)
    for k, i in ((0, 0), (4, 1), (8, 2)):
        np.testing.assert_array_equal(cams[k].world_to_camera, garden_cams[i].world_to_camera)
    steps = np.linalg.norm(np.diff([c.center for c in cams], axis=0), axis=1)
    assert steps.max() < 3 * np.median(steps)  # smooth: no jumps
