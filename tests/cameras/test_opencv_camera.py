"""The OpenCV camera model (splatgl/cameras/opencv.py, shaders/cameras/opencv.glsl): lens
distortion through the camera-model interface alone.

The projection against OpenCV's own ``cv2.projectPoints`` (opencv-python-headless, a test
dependency) for COLMAP's four models with realistic and strong coefficients; the Jacobian
against central differences; the fold and the cull frustum against the forward map; the GLSL
piece against the twin (point-like splats, and whole images against the NumPy reference with
tests/cameras/test_lens.py's bounds); COLMAP, transforms.json and camera-JSON round trips.  End to end
(eval, CLI, viewer, the order stages, the ray-traced twin): tests/cameras/test_opencv_end_to_end.py.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from helpers import IN_VIEW, SURFELS, random_scene, scene_with_colors
from splatgl.api import render_reference_rgba
from splatgl.cameras.camera import Camera
from splatgl.cameras.camera_files import camera_from_json
from splatgl.cameras.opencv import CULL_MARGIN_PX, OpenCV, fold_radius, undistort
from splatgl.cameras.pinhole import Pinhole
from splatgl.datasets import colmap, load_views, nerf
from splatgl.datasets.named_camera import NamedCamera
from splatgl.errors import CameraError
from splatgl.measure.evaluation.metrics import image_errors, psnr
from splatgl.scene.settings import RenderSettings
from splatgl.renderers.registry import check
from splatgl.splatmath import project as pm

from test_compare import MAX_OFF_1, MIN_PSNR
from test_lens import MAX_ABS_LENS

cv2 = pytest.importorskip("cv2")

W, H = 96, 72
#: (COLMAP line's parameters after the intrinsics, model): realistic and strong per model.
COLMAP_CASES = {
    "SIMPLE_RADIAL": [(0.02,), (-0.35,)],
    "RADIAL": [(-0.04, 0.01), (0.45, 0.2)],
    "OPENCV": [(-0.08, 0.02, 0.0007, -0.0004), (-0.4, 0.15, 0.012, -0.009)],
    "FULL_OPENCV": [(-0.1, 0.03, 0.001, -0.001, -0.004, 0.0, 0.0, 0.0),
                    (0.6, -0.3, 0.01, -0.02, 0.1, 0.4, -0.1, 0.05)],
}
CASES = [(name, i) for name in COLMAP_CASES for i in range(2)]
IDS = [f"{name}-{'strong' if i else 'realistic'}" for name, i in CASES]


def _colmap_camera(tmp_path, name: str, terms: tuple) -> Camera:
    """A camera read from a hand-written cameras.txt (fx 60, fy 58 or f 60; principal point off
    centre), through COLMAP's parameter order."""
    head = "60 58 47.5 37" if name.startswith(("OPENCV", "FULL")) else "60 47.5 37"
    (tmp_path / "cameras.txt").write_text(f"1 {name} {W} {H} {head} {' '.join(map(str, terms))}\n")
    (tmp_path / "images.txt").write_text("1 1 0 0 0 0 0 0 1 a.png\n\n")
    return colmap.load_colmap(tmp_path)[0].camera


def _points(camera: Camera, n: int = 400, seed: int = 0, spread: float = 1.6) -> np.ndarray:
    """(n, 3) camera-space points whose x/z, y/z cover ``spread`` times the image's tangent
    bounds (inside the fold radius), depths 0.5..8."""
    a_lo, a_hi, b_lo, b_hi = camera.model.bounds(camera)
    rng = np.random.default_rng(seed)
    c, h = np.array([a_lo + a_hi, b_lo + b_hi]) / 2, np.array([a_hi - a_lo, b_hi - b_lo]) / 2
    n2 = c + spread * h * rng.uniform(-1, 1, (4 * n, 2))
    n2 = n2[np.einsum("ni,ni->n", n2, n2) < 0.98 * fold_radius(camera.model) ** 2][:n]
    z = rng.uniform(0.5, 8.0, len(n2))
    return np.concatenate([n2 * z[:, None], z[:, None]], 1)


# ------------------------------------------------------------------ the math
@pytest.mark.parametrize("name,i", CASES, ids=IDS)
def test_projection_equals_cv2_project_points(tmp_path, name, i):
    cam = _colmap_camera(tmp_path, name, COLMAP_CASES[name][i])
    assert isinstance(cam.model, OpenCV)
    rng = np.random.default_rng(1)
    rvec, tvec = rng.normal(0, 0.3, 3), rng.normal(0, 0.5, 3)
    pose = np.eye(4)
    pose[:3, :3], pose[:3, 3] = cv2.Rodrigues(rvec)[0], tvec
    cam = cam.with_pose(pose)
    p_cam = _points(cam)
    world = (p_cam - tvec) @ cv2.Rodrigues(rvec)[0]        # R^T (p - t)
    k = np.array([[cam.fx, 0, cam.cx], [0, cam.fy, cam.cy], [0, 0, 1.0]])
    want = cv2.projectPoints(world, rvec, tvec, k, np.array(cam.model.coefficients))[0][:, 0]
    got = pm.project_means(pm.to_camera(world, cam), cam)
    assert np.abs(got - want).max() < 1e-6


@pytest.mark.parametrize("name,i", CASES, ids=IDS)
def test_jacobian_equals_central_differences(tmp_path, name, i):
    cam = _colmap_camera(tmp_path, name, COLMAP_CASES[name][i])
    p = _points(cam, spread=1.25)   # inside the Jacobian's clamp box (1.3 x the bounds)
    j = pm.jacobian(p, cam)
    h = 1e-6
    num = np.stack([(pm.project_means(p + h * e, cam) - pm.project_means(p - h * e, cam)) / (2 * h)
                    for e in np.eye(3)], -1)
    scale = np.abs(num).max(axis=(1, 2), keepdims=True)
    assert (np.abs(j - num) <= 1e-6 * scale).all()


def test_jacobian_is_clamped_outside_the_image_as_the_pinholes():
    """Far outside the image the distortion's derivative grows fast (pincushion); the unclamped
    first-order footprint of a splat thousands of pixels away reached into the image.  Outside
    the clamp box J is taken at the box's edge, as the pinhole's is."""
    cam = Camera(W, H, 60, 60, 48, 36, np.eye(4), OpenCV(k1=0.3, k2=0.1))
    a_lo, a_hi, b_lo, b_hi = cam.model.jacobian_box(cam)
    assert a_hi == pytest.approx(-a_lo) and a_hi < 1.3 * 48 / 60   # a pincushion sees less than the pinhole
    far, edge = np.array([[5.0, -9.0, 2.0]]), np.array([[a_hi * 2.0, b_lo * 2.0, 2.0]])
    np.testing.assert_allclose(pm.jacobian(far, cam), pm.jacobian(edge, cam), rtol=1e-12)
    pin = Camera(W, H, 60, 60, 48, 36)
    np.testing.assert_allclose(Camera(W, H, 60, 60, 48, 36, np.eye(4), OpenCV()).model.jacobian_box(pin),
                               (-1.3 * 0.8, 1.3 * 0.8, -1.3 * 0.6, 1.3 * 0.6), rtol=1e-9)


def test_centres_beyond_the_fold_are_not_drawn():
    """k1 = -0.5: r (1 - r^2 / 2) grows up to r = sqrt(2/3), then falls.  cv2 puts a point at
    r = 1.3 back inside the image (as r = 0.26); the model does not draw it."""
    model = OpenCV(k1=-0.5)
    assert fold_radius(model) == pytest.approx(math.sqrt(2 / 3), rel=1e-9)
    cam = Camera(W, H, 60, 60, 48, 36, np.eye(4), model)
    p = np.array([[1.3, 0.0, 1.0], [0.8, 0.0, 1.0], [0.2, 0.1, 0.05]])
    u = cv2.projectPoints(p, np.zeros(3), np.zeros(3), np.array([[60, 0, 48], [0, 60, 36], [0, 0, 1.0]]),
                          np.array(model.coefficients))[0][0, 0, 0]
    assert 0 < u < W                                       # folded back in by OpenCV
    assert model.visible(p, cam, 0.1).tolist() == [False, True, False]   # beyond, inside, near


@pytest.mark.parametrize("model", [OpenCV(k1=-0.35, k2=0.1, p1=0.01), OpenCV(k1=0.45, k2=0.2, p2=-0.02),
                                   OpenCV(k1=-0.6), OpenCV(0.6, -0.3, 0.01, -0.02, 0.1, 0.4, -0.1, 0.05)],
                         ids=["barrel", "pincushion", "past_the_fold", "rational"])
def test_cull_frustum_holds_every_ray_the_image_sees(model):
    """Forward check, independent of the undistortion that builds the frustum: points inside
    the fold radius that land in the image widened by the margin lie inside the frustum."""
    cam = Camera(W, H, 50, 52, 44, 39, np.eye(4), model)
    frustum = model.cull_frustum(cam)
    assert isinstance(frustum.model, Pinhole) and frustum.fx == cam.fx
    rng = np.random.default_rng(2)
    extent = max(frustum.cx, frustum.width - frustum.cx) / frustum.fx + max(frustum.cy, frustum.height - frustum.cy) / frustum.fy
    r = min(fold_radius(model), 3.0 * extent)   # a region well beyond the frustum's
    n = rng.uniform(-r, r, (200000, 2))
    n = n[np.einsum("ni,ni->n", n, n) < r * r]
    uv = pm.project_means(np.concatenate([n, np.ones((len(n), 1))], 1), cam)
    m = CULL_MARGIN_PX
    seen = (uv[:, 0] > -m) & (uv[:, 0] < W + m) & (uv[:, 1] > -m) & (uv[:, 1] < H + m)
    assert seen.sum() > 1000
    fu = n[seen, 0] * frustum.fx + frustum.cx
    fv = n[seen, 1] * frustum.fy + frustum.cy
    assert (fu >= 0).all() and (fu <= frustum.width).all() and (fv >= 0).all() and (fv <= frustum.height).all()
    d = (np.stack(np.meshgrid(np.arange(W) + 0.5, np.arange(H) + 0.5), -1).reshape(-1, 2)
         - [cam.cx, cam.cy]) / [cam.fx, cam.fy]
    back, ok = undistort(d, model)
    assert np.abs(pm.project_means(np.c_[back[ok], np.ones(ok.sum())], cam) - (d[ok] * [cam.fx, cam.fy] + [cam.cx, cam.cy])).max() < 1e-6


# ------------------------------------------------------------------ files
@pytest.mark.parametrize("name,i", CASES, ids=IDS)
@pytest.mark.parametrize("binary", [False, True])
def test_colmap_round_trip(tmp_path, name, i, binary):
    terms = COLMAP_CASES[name][i]
    (tmp_path / "a").mkdir()
    cam = _colmap_camera(tmp_path / "a", name, terms)
    coeffs = dict(zip(("k1", "k2", "p1", "p2", "k3", "k4", "k5", "k6"), cam.model.coefficients))
    order = {"SIMPLE_RADIAL": ("k1",), "RADIAL": ("k1", "k2"), "OPENCV": ("k1", "k2", "p1", "p2"),
             "FULL_OPENCV": ("k1", "k2", "p1", "p2", "k3", "k4", "k5", "k6")}[name]
    assert tuple(coeffs[k] for k in order) == terms and not any(v for k, v in coeffs.items() if k not in order)
    colmap.write_colmap(tmp_path / "b", [NamedCamera("a.png", cam)], binary=binary)
    if not binary:
        assert (tmp_path / "b" / "cameras.txt").read_text().splitlines()[1].split()[1] == name
    back = colmap.load_colmap(tmp_path / "b")[0].camera
    assert back.model == cam.model and (back.fx, back.fy, back.cx, back.cy) == (cam.fx, cam.fy, cam.cx, cam.cy)


def test_colmap_zero_distortion_is_a_pinhole(tmp_path):
    cam = _colmap_camera(tmp_path, "FULL_OPENCV", (0,) * 8)
    assert isinstance(cam.model, Pinhole) and (cam.fx, cam.fy) == (60, 58)


def _transforms(tmp_path, **fields):
    obj = {"w": W, "h": H, "fl_x": 60, "fl_y": 58, "cx": 47.5, "cy": 37, **fields,
           "frames": [{"file_path": "a", "transform_matrix": np.eye(4).tolist()}]}
    (tmp_path / "transforms.json").write_text(json.dumps(obj))
    return tmp_path / "transforms.json"


def test_transforms_json_round_trip_and_nerfstudio_k4(tmp_path):
    """nerfstudio's OPENCV: k1 k2 k3 radial, p1 p2 tangential; its k4 is an r^8 term (its
    camera_utils: d = 1 + k1 r + k2 r^2 + k3 r^3 + k4 r^4 in r = x^2 + y^2), not OpenCV's k4."""
    (cam,) = [v.camera for v in load_views(_transforms(tmp_path, k1=-0.2, k2=0.05, k3=0.01, p1=0.002, p2=-0.001))]
    assert cam.model == OpenCV(k1=-0.2, k2=0.05, p1=0.002, p2=-0.001, k3=0.01)
    obj = nerf.transforms_json([NamedCamera("a", cam)])
    assert obj["frames"][0]["camera_model"] == "OPENCV" and obj["frames"][0]["k3"] == 0.01
    (tmp_path / "transforms.json").write_text(json.dumps(obj))
    assert load_views(tmp_path)[0].camera.model == cam.model
    (cam0,) = [v.camera for v in load_views(_transforms(tmp_path, k1=0, p2=0))]
    assert isinstance(cam0.model, Pinhole)
    with pytest.raises(CameraError, match=r"transforms.json: frame 0: field 'k4' = 0.001: nerfstudio's r\^8 "
                                          "radial term, which splatgl's opencv camera does not have"):
        load_views(_transforms(tmp_path, k1=0.1, k4=0.001))
    with pytest.raises(CameraError, match="frame 0: field 'k1' = 0.1: lens distortion is not supported"):
        load_views(_transforms(tmp_path, k1=0.1, camera_model="PINHOLE"))   # the pinhole's refusal
    with pytest.raises(CameraError, match="no fields for OpenCV's rational terms k4..k6"):
        nerf.transforms_json([NamedCamera("a", cam.with_model(OpenCV(k1=0.1, k4=0.2)))])


def test_camera_json_round_trip_and_bad_distortion(tmp_path):
    for model, size in ((OpenCV(k1=-0.1, p2=0.01), 4), (OpenCV(k1=-0.1, k3=0.02), 5),
                        (OpenCV(k1=0.2, k6=0.01), 8)):
        cam = Camera(W, H, 60, 58, 47.5, 37, np.eye(4), model)
        obj = json.loads(json.dumps(cam.to_json()))
        assert obj["projection"] == "opencv" and len(obj["distortion"]) == size
        assert camera_from_json(obj).model == model
    obj["distortion"] = [0.1, 0.2, 0.3]
    with pytest.raises(CameraError, match=r"c.json: field 'distortion' must be a list of 4, 5 or 8 "
                                          r"numbers \(OpenCV's k1 k2 p1 p2 \[k3 \[k4 k5 k6\]\]; "
                                          r"12 or 14 with s1..s4, tauX, tauY 0\), got 3"):
        camera_from_json(obj, tmp_path / "c.json")
    obj["distortion"] = [0.1, None, 0, 0]
    with pytest.raises(CameraError, match="c.json: field 'distortion' holds NaN at entry 1"):
        camera_from_json(obj, tmp_path / "c.json")
    with pytest.raises(CameraError, match="camera distortion k2 must be a finite number, got inf"):
        OpenCV(k2=math.inf)


def test_surfels_are_refused_and_the_tile_renderer_draws_it():
    model = OpenCV(k1=0.1)
    with pytest.raises(CameraError, match="opencv cameras render 3DGS scenes only"):
        check("quad", model=model, scene=random_scene(2, **SURFELS))
    check("tile", model=model)


# ------------------------------------------------------------------ the shader piece
STRONG = [OpenCV(k1=-0.35, k2=0.1, p1=0.01, p2=-0.005), OpenCV(k1=0.45, k2=0.2),
          OpenCV(0.6, -0.3, 0.01, -0.02, 0.1, 0.4, -0.1, 0.05), OpenCV(k1=-0.6)]
STRONG_IDS = ["barrel", "pincushion", "rational", "past_the_fold"]


@pytest.mark.parametrize("kind", ["quad", "tile"])
def test_point_splats_land_where_the_twin_projects(gl_renderer, kind):
    """Tiny splats spread over a strongly distorted image, corners included: each one's alpha
    centroid is the twin's projected centre (the GLSL project_mean) within 0.1 px."""
    cam = Camera(W, H, 50, 50, 46, 37, np.eye(4), STRONG[0])
    want = np.array([[8, 7], [88, 9], [12, 64], [85, 66], [46, 37], [30, 50]], float)
    d = (want - [cam.cx, cam.cy]) / [cam.fx, cam.fy]
    n, ok = undistort(d, cam.model)
    assert ok.all()
    z = np.linspace(2.0, 4.0, len(n))
    means = np.c_[n * z[:, None], z]
    np.testing.assert_allclose(pm.project_means(means, cam), want, atol=1e-9)
    sigma = 0.35 * z / cam.fx
    scene = scene_with_colors(means, [[1, 0, 0, 0]] * len(n), np.repeat(sigma[:, None], 3, 1),
                              [0.9] * len(n), [[1, 1, 1]] * len(n))
    alpha = gl_renderer.render(scene, cam, kind=kind)[..., 3].astype(np.float64)
    rows, cols = np.mgrid[0:H, 0:W] + 0.5
    for u, v in want:
        win = (np.abs(cols - u) < 4) & (np.abs(rows - v) < 4)
        a = np.where(win, alpha, 0.0)
        assert a.sum() > 0.3
        assert ((a * cols).sum() / a.sum(), (a * rows).sum() / a.sum()) == pytest.approx((u, v), abs=0.1)


@pytest.mark.parametrize("model", STRONG, ids=STRONG_IDS)
def test_quad_and_tile_match_the_reference(gl_renderer, model):
    """Whole images of a random scene through strong distortion: the quad path against the
    NumPy reference with test_lens's bounds, the tile renderer to 85 dB, and the order stage's
    cull against its frustum leaves the image as drawing every splat does."""
    scene = random_scene(1500, seed=3, **{**IN_VIEW, "spread": (2.2, 1.8, 0.7), "log_scale": (-2.6, 0.6)})
    cam = Camera(W, H, 42, 44, 47, 35, np.eye(4), model)
    ref = render_reference_rgba(scene, cam, RenderSettings())
    assert ref[..., 3].mean() > 0.15
    quad = gl_renderer.render(scene, cam)
    err = image_errors(quad, ref)
    assert err.psnr > MIN_PSNR and err.max_abs < MAX_ABS_LENS and err.off_1 < MAX_OFF_1, err
    np.testing.assert_array_equal(quad, gl_renderer.render(scene, cam, RenderSettings(cull=False)))
    assert psnr(gl_renderer.render(scene, cam, kind="tile"), ref) > 85.0
