"""Scene transforms: folded into the camera, SH evaluated in the scene's own frame."""

from __future__ import annotations

import numpy as np
import pytest

from splatgl.cameras.camera import Camera
from splatgl.cameras.poses import orbit
from splatgl.cli import main
from splatgl.errors import SplatglError
from splatgl.splatmath.project import sh_color, view_dirs
from splatgl.api import default_camera
from splatgl.scene.splats import Scene
from splatgl.scene.settings import RendererKind, RenderSettings
from splatgl.scene.transform import SceneTransform, parse_transform
from splatgl.cameras.view import apply_transform


def _sh3_scene(n=300, seed=8):
    rng = np.random.default_rng(seed)
    return Scene(rng.normal(size=(n, 3)) * 0.6, rng.normal(size=(n, 4)), rng.normal(-2.8, 0.3, (n, 3)),
                 rng.normal(0.5, 1.0, n), rng.normal(0, 0.5, (n, 16, 3)))


def _quat_mul(a, b):
    w1, x1, y1, z1 = a.T
    w2, x2, y2, z2 = b.T
    return np.stack([w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2, w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
                     w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2, w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2], -1)


def _rot_to_quat(r):
    w = np.sqrt(max(1e-12, 1 + r[0, 0] + r[1, 1] + r[2, 2])) / 2
    return np.array([w, (r[2, 1] - r[1, 2]) / (4 * w), (r[0, 2] - r[2, 0]) / (4 * w), (r[1, 0] - r[0, 1]) / (4 * w)])


MODEL = SceneTransform.from_euler((25.0, -40.0, 70.0), (0.5, -0.2, 1.5), 1.7)
RIGID = SceneTransform.from_euler((25.0, -40.0, 70.0), (0.5, -0.2, 1.5), 1.0)


@pytest.mark.parametrize("kind", [RendererKind.QUAD, RendererKind.TILE, RendererKind.REFERENCE])
def test_rotating_scene_and_camera_together_changes_nothing(gl_renderer, kind):
    scene = _sh3_scene()
    cam = Camera(96, 72, 80.0, 80.0, 48.0, 36.0, orbit([0, 0, 0], 4.0, 30.0, 20.0))
    plain = gl_renderer.render_layers(scene, cam, RenderSettings(), kind)
    # Rotate (and shift) the scene by M and the camera with it: its pose becomes W M^-1.
    moved_cam = cam.with_pose(cam.world_to_camera @ np.linalg.inv(RIGID.matrix))
    moved = gl_renderer.render_layers(scene, moved_cam, RenderSettings(transform=RIGID), kind)
    # float32 rounding of the composed matrices: a few 1e-6 in colour (SH degree 3).
    np.testing.assert_allclose(moved.rgba, plain.rgba, atol=2e-4)
    np.testing.assert_allclose(moved.depth, plain.depth, atol=2e-4)


def test_world_space_sh_direction_would_differ():
    """The test above can fail: the world-space direction gives other colours for this data."""
    scene = _sh3_scene()
    cam = Camera(96, 72, 80.0, 80.0, 48.0, 36.0, orbit([0, 0, 0], 4.0, 30.0, 20.0))
    world_cam = cam.with_pose(cam.world_to_camera @ np.linalg.inv(RIGID.matrix))
    means_w = RIGID.apply_points(scene.means)
    d_world = (means_w - world_cam.center) / np.linalg.norm(means_w - world_cam.center, axis=1, keepdims=True)
    d_scene = view_dirs(scene.means.astype(np.float64), apply_transform(world_cam, RIGID))
    c_world = sh_color(scene.sh.astype(np.float64), d_world)
    c_scene = sh_color(scene.sh.astype(np.float64), d_scene)
    assert np.abs(c_world - c_scene).max() > 0.2
    # and the scene-frame direction is the plain camera's direction
    np.testing.assert_allclose(d_scene, view_dirs(scene.means.astype(np.float64), cam), atol=1e-9)


def test_transform_equals_moving_the_splats(gl_renderer):
    """For SH degree 0, a transform renders like a scene whose splats were moved explicitly."""
    rng = np.random.default_rng(4)
    n = 200
    base = Scene(rng.normal(size=(n, 3)) * 0.5, rng.normal(size=(n, 4)), rng.normal(-2.8, 0.3, (n, 3)),
                 rng.normal(0.5, 1.0, n), rng.normal(0, 0.5, (n, 1, 3)))
    r = np.asarray(MODEL.rotation)
    moved = Scene.from_activated(MODEL.apply_points(base.means),
                                 _quat_mul(np.tile(_rot_to_quat(r), (n, 1)), base.rotations.astype(np.float64)),
                                 base.scales * MODEL.scale, base.opacities, base.sh)
    cam = default_camera(moved, 96, 72)
    for kind in (RendererKind.QUAD, RendererKind.REFERENCE):
        a = gl_renderer.render(base, cam, RenderSettings(transform=MODEL), kind)
        b = gl_renderer.render(moved, cam, RenderSettings(), kind)
        np.testing.assert_allclose(a, b, atol=3e-4)
        assert a[..., 3].max() > 0.5


def test_parse_transform_and_cli_errors(tmp_path, capsys):
    t = parse_transform('{"rotate_deg": [0, 0, 90], "translate": [1, 2, 3], "scale": 2}')
    np.testing.assert_allclose(t.apply_points(np.array([[1.0, 0, 0]])), [[1, 4, 3]], atol=1e-12)
    f = tmp_path / "t.json"
    f.write_text('{"scale": 3}')
    assert parse_transform(str(f)).scale == 3.0
    for bad in ('{"scale": -1}', '{"rotation": [[2, 0, 0], [0, 1, 0], [0, 0, 1]]}', "[1, 2]", "nope"):
        with pytest.raises(SplatglError):
            parse_transform(bad)
    assert main(["render", "-o", str(tmp_path / "x.png"), "--transform", '{"scale": 0}']) == 2
    assert capsys.readouterr().err == ("splatgl: error: --transform: scale must be a positive finite "
                                       "number, got 0\n")


DEGREES = "3 finite numbers (degrees)"
MATRIX = "a 3x3 rotation matrix (3 rows of 3 finite numbers)"
POSITIVE = "a positive finite number"


@pytest.mark.parametrize("text, message", [
    # each was a raw Python error ("not enough values to unpack", "could not convert string to
    # float: 'a'", "'int' object is not iterable", "math domain error"), or accepted a boolean or
    # a string as a number
    ('{"rotate_deg": [0,0]}', f"rotate_deg must be {DEGREES}, got [0, 0]"),
    ('{"rotate_deg": [0,0,0,0]}', f"rotate_deg must be {DEGREES}, got [0, 0, 0, 0]"),
    ('{"rotate_deg": "abc"}', f'rotate_deg must be {DEGREES}, got "abc"'),
    ('{"rotate_deg": 5}', f"rotate_deg must be {DEGREES}, got 5"),
    ('{"rotate_deg": [true, 0, 0]}', f"rotate_deg must be {DEGREES}, got [true, 0, 0]"),
    ('{"rotate_deg": [NaN, 0, 0]}', f"rotate_deg must be {DEGREES}, got [NaN, 0, 0]"),
    ('{"rotate_deg": [1e400, 0, 0]}', f"rotate_deg must be {DEGREES}, got [Infinity, 0, 0]"),
    ('{"rotate_deg": null}', f"rotate_deg must be {DEGREES}, got null"),
    ('{"rotation": [[1, 0], [0, 1]]}', f"rotation must be {MATRIX}, got [[1, 0], [0, 1]]"),
    ('{"rotation": "abc"}', f'rotation must be {MATRIX}, got "abc"'),
    ('{"rotation": [1, 0, 0, 0]}', f"rotation must be {MATRIX}, got [1, 0, 0, 0]"),
    ('{"rotation": [[1, 0, 0], [0, 1, 0], [0, 0, "1"]]}',
     f'rotation must be {MATRIX}, got [[1, 0, 0], [0, 1, 0], [0, 0, "1"]]'),
    ('{"rotation": [[true, 0, 0], [0, 1, 0], [0, 0, 1]]}',
     f"rotation must be {MATRIX}, got [[true, 0, 0], [0, 1, 0], [0, 0, 1]]"),
    ('{"rotation": [[1, 0, 0], [0, 1, 0], [0, 0, NaN]]}',
     f"rotation must be {MATRIX}, got [[1, 0, 0], [0, 1, 0], [0, 0, NaN]]"),
    ('{"rotation": [[-1, 0, 0], [0, 1, 0], [0, 0, 1]]}', "rotation must be a proper rotation "
     "matrix (orthonormal, det +1), got [[-1, 0, 0], [0, 1, 0], [0, 0, 1]]"),
    ('{"translate": [1, 2]}', "translate must be 3 finite numbers, got [1, 2]"),
    ('{"translate": "abc"}', 'translate must be 3 finite numbers, got "abc"'),
    ('{"translate": ["1", 0, 0]}', 'translate must be 3 finite numbers, got ["1", 0, 0]'),
    ('{"translate": [false, 0, 0]}', "translate must be 3 finite numbers, got [false, 0, 0]"),
    ('{"translate": [0, -Infinity, 0]}', "translate must be 3 finite numbers, got [0, -Infinity, 0]"),
    ('{"scale": "abc"}', f'scale must be {POSITIVE}, got "abc"'),
    ('{"scale": "2"}', f'scale must be {POSITIVE}, got "2"'),
    ('{"scale": true}', f"scale must be {POSITIVE}, got true"),
    ('{"scale": [1]}', f"scale must be {POSITIVE}, got [1]"),
    ('{"scale": NaN}', f"scale must be {POSITIVE}, got NaN"),
    ('{"scale": Infinity}', f"scale must be {POSITIVE}, got Infinity"),
    ('{"scale": -1}', f"scale must be {POSITIVE}, got -1"),
    ('{"scale": null}', f"scale must be {POSITIVE}, got null"),
    ("[1, 2]", "expected a JSON object with keys rotate_deg, rotation, translate, scale, got [1, 2]"),
])
def test_each_transform_key_refuses_a_bad_value_in_one_line(text, message):
    with pytest.raises(SplatglError) as err:
        parse_transform(text)
    assert str(err.value) == f"--transform: {message}"


def test_a_long_bad_transform_is_cut_short_and_never_a_traceback():
    with pytest.raises(SplatglError, match=r"^--transform: translate must be 3 finite numbers, got "
                                           r"\[1, 1, [1, ]*1?\.\.\.$"):
        parse_transform('{"translate": [%s]}' % ",".join(["1"] * 1000))
    with pytest.raises(SplatglError, match=r"^--transform: not JSON or a JSON file"):
        parse_transform("x" * 5000)  # too long for a file name: was an OSError traceback


def test_the_edit_crop_box_placement_names_its_option():
    from splatgl.edit.options import crop_box

    with pytest.raises(SplatglError) as err:
        crop_box('{"min": [0, 0, 0], "max": [1, 1, 1], "rotate_deg": [0, 0]}')
    assert str(err.value) == f"--crop-box: rotate_deg must be {DEGREES}, got [0, 0]"


@pytest.mark.parametrize("kwargs, message", [
    (dict(rotation="abc"), "transform rotation must be a 3x3 matrix of finite numbers, got 'abc'"),
    (dict(rotation=np.eye(3) * 2), "transform rotation must be a proper rotation (orthonormal, "
     "det +1), got [[2.0, 0.0, 0.0], [0.0, 2.0, 0.0], [0.0, 0.0, 2.0]]"),
    (dict(translation=(1, 2)), "transform translation must be 3 finite numbers, got (1, 2)"),
    (dict(translation=(True, 0, 0)), "transform translation must be 3 finite numbers, got (True, 0, 0)"),
    (dict(scale="2"), "transform scale must be a positive finite number, got '2'"),
    (dict(scale=float("nan")), "transform scale must be a positive finite number, got nan"),
])
def test_scene_transform_refuses_bad_values_from_python(kwargs, message):
    with pytest.raises(SplatglError) as err:
        SceneTransform(**kwargs)
    assert str(err.value) == message


def test_numpy_values_make_a_transform():
    t = SceneTransform(np.eye(3), np.array([1, 2, 3]), np.float32(2.0))
    assert t.translation == (1.0, 2.0, 3.0) and t.scale == 2.0
