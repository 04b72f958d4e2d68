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
    assert "scale must be positive" in capsys.readouterr().err
