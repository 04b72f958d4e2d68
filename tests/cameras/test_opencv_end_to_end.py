"""The OpenCV camera model end to end (tests/cameras/test_opencv_camera.py has its math, files and
shader piece): `eval` on a raw SIMPLE_RADIAL COLMAP dataset of distorted photographs, `render
--camera`, `render --path` and `compare` from the CLI, the viewer, the order stages' cull
against the distorted frustum, and the ray-traced twin of benchmarks/distortion_accuracy.py.
"""

from __future__ import annotations

import importlib.util
import json

import numpy as np
import pytest

from helpers import IN_VIEW, REPO, random_scene, scene_with_colors
from splatgl.api import render_reference_rgba
from splatgl.cameras.camera import Camera
from splatgl.cameras.opencv import OpenCV
from splatgl.cli import main
from splatgl.datasets import colmap
from splatgl.datasets.named_camera import NamedCamera
from splatgl.measure.evaluation.metrics import image_errors, psnr
from splatgl.scene.settings import RenderSettings
from splatgl.imagefiles.images import read_image, write_image

from test_compare import MIN_PSNR
from test_viewer_window import _window_pixels  # (the Xvfb fixture comes from conftest)

W, H = 96, 72


# ------------------------------------------------------------------ datasets, the CLI, the viewer
DISTORTED = OpenCV(k1=-0.3)   # SIMPLE_RADIAL


@pytest.fixture(scope="module")
def raw_colmap(tmp_path_factory):
    """A raw COLMAP dataset of the demo scene: SIMPLE_RADIAL cameras (k = -0.3, a 77-degree
    horizontal field of view) and their distorted "photographs", rendered by the reference."""
    from splatgl.cameras.poses import orbit
    from splatgl.commands._common import demo_scene_path
    from splatgl.formats import load_scene

    root = tmp_path_factory.mktemp("raw_colmap")
    scene = load_scene(demo_scene_path())
    lo, hi = scene.robust_bounds
    views = []
    (root / "images").mkdir()
    for i in range(3):
        cam = Camera(64, 48, 40, 40, 32, 24, orbit(0.5 * (lo + hi), 4.0, 50.0 * i, 15.0), DISTORTED)
        rgba = render_reference_rgba(scene, cam, RenderSettings(background=(0.5, 0.5, 0.5)))
        write_image(root / "images" / f"{i}.png", np.concatenate([rgba[..., :3], np.ones_like(rgba[..., :1])], -1), 16)
        views.append(NamedCamera(f"{i}.png", cam))
    colmap.write_colmap(root / "sparse" / "0", views, binary=False)
    assert " SIMPLE_RADIAL 64 48 40.0 32.0 24.0 -0.3" in (root / "sparse" / "0" / "cameras.txt").read_text()
    return root, demo_scene_path(), views


@pytest.mark.slow
def test_eval_on_a_raw_colmap_dataset(raw_colmap, tmp_path, capsys):
    """`eval` on SIMPLE_RADIAL cameras (refused before) scores the distorted photographs as
    renders of the same scene; read as pinholes (distortion dropped) they score far lower."""
    root, scene, _ = raw_colmap

    def mean_psnr(dataset):
        assert main(["eval", str(scene), "--dataset", str(dataset), "--background", "0.5,0.5,0.5",
                     "--json", str(tmp_path / "e.json"), "--force"]) == 0
        return json.loads((tmp_path / "e.json").read_text())["mean"]["psnr"]

    assert mean_psnr(root) > 50.0
    pin = tmp_path / "pinhole"
    (pin / "sparse" / "0").mkdir(parents=True)
    (pin / "images").symlink_to(root / "images")
    text = (root / "sparse" / "0" / "cameras.txt").read_text().replace(" -0.3\n", " 0\n")
    (pin / "sparse" / "0" / "cameras.txt").write_text(text)
    (pin / "sparse" / "0" / "images.txt").write_text((root / "sparse" / "0" / "images.txt").read_text())
    assert mean_psnr(pin) < 30.0


@pytest.mark.slow
def test_render_camera_path_and_compare_from_the_cli(raw_colmap, tmp_path, capsys, gl_renderer):
    from splatgl.formats import load_scene
    root, scene_path, views = raw_colmap
    scene = load_scene(scene_path)
    cam = views[1].camera
    (tmp_path / "cam.json").write_text(json.dumps(cam.to_json()))
    assert main(["render", str(scene_path), "--camera", str(tmp_path / "cam.json"), "-o",
                 str(tmp_path / "one.png")]) == 0
    want = np.round(np.clip(gl_renderer.render(scene, cam)[..., :3], 0, 1) * 255) / 255
    assert np.abs(read_image(tmp_path / "one.png") - want).max() <= 1 / 255 + 1e-6
    assert main(["render", str(scene_path), "--path", str(root), "-o", str(tmp_path / "frames")]) == 0
    frames = sorted((tmp_path / "frames").iterdir())
    assert [p.name for p in frames] == ["00000.png", "00001.png", "00002.png"]
    np.testing.assert_array_equal(read_image(frames[1]), read_image(tmp_path / "one.png"))
    capsys.readouterr()
    assert main(["compare", str(scene_path), "--camera", str(tmp_path / "cam.json"), "--json",
                 str(tmp_path / "c.json")]) == 0
    report = json.loads((tmp_path / "c.json").read_text())
    assert report["psnr"] > MIN_PSNR, report


@pytest.mark.window
def test_viewer_shows_the_distorted_camera(xvfb_display, raw_colmap, tmp_path):
    """`view --camera` with a distorted camera: the window's first frame is that camera's
    render, and F12's camera JSON keeps the distortion (render --camera of it is the same)."""
    from splatgl.errors import ContextError
    from splatgl.formats import load_scene
    from splatgl.viewer.app import Viewer, ViewerOptions

    _, scene_path, views = raw_colmap
    scene = load_scene(scene_path)
    cams = [v.camera for v in views]
    try:
        v = Viewer(scene, RenderSettings(), cams[2], cams, 2,
                   options=ViewerOptions(visible=True, screenshot_dir=tmp_path, vsync=False,
                                         render_args=(str(scene_path),)))
    except ContextError as exc:
        pytest.skip(f"no OpenGL 4.3+ window context on Xvfb: {exc}")
    try:
        import glfw

        assert v.step()
        v.on_key(glfw.KEY_I, glfw.PRESS, 0)               # hide the status panel
        v.step()
        assert v.camera().model == DISTORTED
        want = v.renderer.render(scene, v.camera(), RenderSettings())[..., :3]
        assert want.std() > 0.01   # the scene is in view
        shown = _window_pixels(v).astype(np.int32)
        assert np.abs(shown - np.round(np.clip(want, 0, 1) * 255).astype(np.int32)).max() <= 1
        _, js = v.screenshot()
        obj = json.loads(js.read_text())
        assert obj["projection"] == "opencv" and obj["distortion"][0] == -0.3
    finally:
        v.close()


# ------------------------------------------------------------------ the ray-traced twin
def _accuracy():
    spec = importlib.util.spec_from_file_location("distortion_accuracy",
                                                  REPO / "benchmarks" / "distortion_accuracy.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.mark.parametrize("model", [None, OpenCV(k1=-0.3, k2=0.08), OpenCV(k1=0.3, k2=0.1)],
                         ids=["pinhole", "barrel", "pincushion"])
def test_raytraced_twin_agrees_with_splats_for_small_splats(model):
    """The per-pixel twin (undistorted ray per pixel, each splat's peak along it) against the
    reference on small splats, where the first-order approximation is good: > 40 dB for the
    pinhole and both distortions (one bad blend rule or ray would cost far more)."""
    scene = random_scene(80, seed=1, **{**IN_VIEW, "log_scale": (-2.0, 0.3)})
    cam = Camera(64, 48, 40, 40, 32, 24)
    cam = cam if model is None else cam.with_model(model)
    twin = _accuracy().raytrace(scene, cam)
    assert psnr(render_reference_rgba(scene, cam, RenderSettings())[..., :3], twin[..., :3]) > 40.0


def test_order_stages_cull_against_the_distorted_frustum(ctx):
    """Barrel distortion sees well beyond the pinhole frustum of the same intrinsics, whose
    planes dropped the image's edges: the plain scene's chunked cull, and a level-of-detail
    cut of leaves (its frustum test and cull) and its leaves drawn directly, now equal drawing
    every splat (no cull)."""
    from helpers import draw
    from splatgl.lod.build import build_hierarchy
    from splatgl.lod.selection import LodSettings
    from splatgl.lod.source import lod_renderer
    from splatgl.renderers.quad import QuadRenderer

    # a clump on the axis and one at x/z = 1.6: beyond the pinhole frustum (1.2), inside the
    # distorted image (which reaches x/z = 2)
    rng = np.random.default_rng(4)
    means = np.concatenate([rng.normal((0, 0, 4), 0.3, (3000, 3)), rng.normal((6.4, 0, 4), 0.1, (3000, 3))])
    scene = scene_with_colors(means, rng.normal(size=(6000, 4)), np.exp(rng.normal(-3.5, 0.3, (6000, 3))),
                              np.full(6000, 0.8), rng.uniform(0, 1, (6000, 3)))
    cam = Camera(W, H, 40, 40, 48, 36, np.eye(4), OpenCV(k1=-0.3, k2=0.05))
    lod = lod_renderer(ctx, build_hierarchy(scene, branching=4), RenderSettings(),
                       LodSettings(threshold_px=1e-3))
    full = QuadRenderer(ctx, scene, RenderSettings())
    every = QuadRenderer(ctx, scene, RenderSettings(cull=False))
    try:
        want = draw(every, cam).rgba
        assert want[30:42, 78:90, 3].mean() > 0.15  # the second clump, at u = 84
        np.testing.assert_array_equal(draw(full, cam).rgba, want)
        for _ in range(2):                        # the cut, then (switched) the leaves
            assert image_errors(draw(lod, cam).rgba, want).psnr > 80.0
        assert lod.rows.last_drew_leaves
    finally:
        lod.release()
        full.release()
        every.release()
