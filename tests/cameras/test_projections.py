"""Orthographic and frustum-bounds cameras in every path (quad, tile, reference)."""

from __future__ import annotations

import numpy as np
import pytest

from splatgl.cameras.camera import Camera
from splatgl.cameras.poses import orbit
from splatgl.cli import main
from splatgl.constants import SH_C0
from splatgl.scene.splats import Scene
from splatgl.scene.settings import RendererKind, RenderSettings

KINDS = [RendererKind.QUAD, RendererKind.TILE, RendererKind.REFERENCE]


def _scene(n=400, seed=12):
    rng = np.random.default_rng(seed)
    return Scene(rng.normal(size=(n, 3)) * 0.5, rng.normal(size=(n, 4)), rng.normal(-3.0, 0.4, (n, 3)),
                 rng.normal(0.5, 1.2, n), rng.normal(0, 0.3, (n, 4, 3)))


@pytest.mark.parametrize("kind", KINDS)
def test_frustum_camera_equals_its_intrinsics(gl_renderer, kind):
    pose = orbit([0, 0, 0], 3.5, 20.0, 15.0)
    frustum = Camera.from_frustum(80, 60, left=-0.09, right=0.05, top=0.04, bottom=-0.07,
                                  near=0.1, far=100.0, world_to_camera=pose)
    same = Camera(80, 60, 80 * 0.1 / 0.14, 60 * 0.1 / 0.11, 0.09 * 80 / 0.14, 0.04 * 60 / 0.11, pose)
    scene = _scene()
    a = gl_renderer.render(scene, frustum, RenderSettings(), kind)
    b = gl_renderer.render(scene, same, RenderSettings(), kind)
    assert a[..., 3].max() > 0.5
    np.testing.assert_allclose(a, b, atol=1e-6)


def _flat_isotropic(positions, s, o, rgb):
    n = len(positions)
    sh = np.zeros((n, 1, 3))
    sh[:, 0] = (np.asarray(rgb) - 0.5) / SH_C0
    return Scene.from_activated(np.asarray(positions, float), np.tile([1.0, 0, 0, 0], (n, 1)),
                                np.full((n, 3), s), np.full(n, o), sh)


@pytest.mark.parametrize("kind", KINDS)
def test_orthographic_equal_depth_matches_analytic(gl_renderer, kind):
    """Non-overlapping isotropic splats at equal depth: alpha = o exp(-r^2 / (2 ((k s)^2 + 0.3)))."""
    k, s, o = 20.0, 0.1, 0.7  # pixels per unit, world sigma, opacity
    centres = [[-1.0, -0.6, 5.0], [0.9, 0.5, 5.0], [0.0, 0.0, 5.0]]
    scene = _flat_isotropic(centres, s, o, [1.0, 1.0, 1.0])
    cam = Camera.orthographic(64, 48, k)
    got = gl_renderer.render(scene, cam, RenderSettings(), kind)[..., 3]
    u, v = np.meshgrid(np.arange(64) + 0.5, np.arange(48) + 0.5)
    var = (k * s) ** 2 + 0.3
    expect = np.zeros_like(u)
    for x, y, _ in centres:
        a = np.minimum(0.99, o * np.exp(-((u - (k * x + 32)) ** 2 + (v - (k * y + 24)) ** 2) / (2 * var)))
        expect += np.where(a >= 1 / 255, a, 0.0)  # the splats do not overlap above 1/255
    # 3DGS square extents and tile snapping cut nothing here: 3 sigma = 6.2 px < the gaps.
    np.testing.assert_allclose(got, expect, atol=2e-5)


def test_orthographic_zoom_scales_the_splats_only(gl_renderer):
    """Doubling pixels-per-unit doubles every screen sigma (plus the fixed 0.3 px^2 low pass)."""
    scene = _flat_isotropic([[0.0, 0.0, 4.0]], 0.08, 0.9, [1.0, 0.5, 0.2])
    sig = {}
    for k in (25.0, 50.0):
        img = gl_renderer.render(scene, Camera.orthographic(96, 96, k), RenderSettings())
        a = img[..., 3].astype(np.float64)
        u = np.arange(96) + 0.5
        w = a.sum(axis=0)
        sig[k] = np.sqrt((w * (u - 48) ** 2).sum() / w.sum())  # second moment along x
        np.testing.assert_allclose(img[48, 48, :3] / img[48, 48, 3], [1.0, 0.5, 0.2], rtol=1e-5)
    # The 1/255 cut truncates the tails the same way at both zooms (in sigma units), so the
    # ratio of the measured moments is the ratio of the true sigmas.
    true = {k: np.sqrt((k * 0.08) ** 2 + 0.3) for k in sig}
    assert sig[50.0] / sig[25.0] == pytest.approx(true[50.0] / true[25.0], rel=2e-3)


def test_orthographic_camera_file_through_the_cli(tmp_path):
    import json

    cam = Camera.orthographic(64, 48, 40.0, orbit([0, 0, 0], 10.0, 180.0, 20.0))
    path = tmp_path / "ortho.json"
    path.write_text(json.dumps(cam.to_json()))
    out = tmp_path / "o.png"
    assert main(["render", "--camera", str(path), "-o", str(out)]) == 0
    assert json.loads(path.read_text())["projection"] == "orthographic"


def test_frustum_camera_file_and_orthographic_flag(tmp_path):
    import json

    from splatgl.cameras.camera_files import load_camera
    from splatgl.imagefiles.images import read_image

    w2c = orbit([0, 0, 0], 6.0, 180.0, 20.0)
    frustum = {"width": 96, "height": 72, "world_to_camera": w2c.tolist(),
               "frustum": {"left": -0.12, "right": 0.1, "top": 0.08, "bottom": -0.09, "near": 0.2, "far": 50}}
    same = Camera(96, 72, 96 * 0.2 / 0.22, 72 * 0.2 / 0.17, 0.12 * 96 / 0.22, 0.08 * 72 / 0.17, w2c)
    (tmp_path / "f.json").write_text(json.dumps(frustum))
    (tmp_path / "i.json").write_text(json.dumps(same.to_json()))
    cam = load_camera(tmp_path / "f.json")
    assert (cam.fx, cam.cy) == pytest.approx((same.fx, same.cy))
    for name in ("f", "i"):
        assert main(["render", "--camera", str(tmp_path / f"{name}.json"), "-o", str(tmp_path / f"{name}.exr")]) == 0
    np.testing.assert_allclose(read_image(tmp_path / "f.exr"), read_image(tmp_path / "i.exr"), atol=1e-6)
    assert main(["render", "--orthographic", "--width", "64", "--height", "48", "-o", str(tmp_path / "o.exr")]) == 0
    ortho = read_image(tmp_path / "o.exr")
    assert ortho[..., 3].max() > 0.5  # the framed demo is visible


def test_model_declarations_shared_by_the_base():
    """A model's shader piece defaults to its name, and the lens-distortion models share their
    declarations through one base (issue 39 item 8): each piece exists, and the distorted
    models read "distortion" from camera files and draw no surfels."""
    from pathlib import Path

    from splatgl.cameras.model import LensDistortion
    from splatgl.cameras.registry import MODELS

    shaders = Path(__file__).resolve().parents[2] / "shaders" / "cameras"
    assert {m.name: m.glsl for m in MODELS.values()} == {
        "perspective": "pinhole", "orthographic": "orthographic", "fisheye": "fisheye",
        "equirectangular": "equirect", "opencv": "opencv"}
    for m in MODELS.values():
        assert (shaders / f"{m.glsl}.glsl").is_file(), m.name
        assert m().defines()["CAMERA_MODEL"] == m.glsl
    lens = sorted(m.name for m in MODELS.values() if issubclass(m, LensDistortion))
    assert lens == ["fisheye", "opencv"]
    assert all(not MODELS[n].draws_surfels and MODELS[n].json_fields == ("distortion",) for n in lens)
