"""The per-pixel order (--order per-pixel) of the reference: against a brute-force per-pixel
sort, the tile renderer's windowed twin, and the crossing splats that pop under the global order."""

from __future__ import annotations

import numpy as np
import pytest

from helpers import random_scene
from splatgl.cameras.camera import Camera
from splatgl.cameras.poses import look_at
from splatgl.constants import ALPHA_MAX, ALPHA_MIN, SH_C0, T_MIN
from splatgl.errors import CameraError
from splatgl.scene.quaternion import quat_to_rotmat
from splatgl.cameras.view import View
from splatgl.scene.splats import Scene, SplatKind
from splatgl.output.layers import Layer, with_layers
from splatgl.renderers.tile import TileRenderer
from splatgl.scene.settings import Order, RenderSettings
from splatgl.reference import ReferenceOptions, render_reference
from splatgl.reference.per_pixel import TILE_LIST_CHUNK, window_order
from splatgl.renderers import tile_keys

PER_PIXEL = RenderSettings(near=0.2, order=Order.PER_PIXEL)


def brute_force(scene: Scene, cam: Camera, ref) -> np.ndarray:
    """Colour of every pixel by a plain loop: the pixel's splats (those binned to its tile, as
    the reference bins them) sorted by the depth of their Gaussian's peak along its ray,
    computed from the inverted 3D covariance (clamped to 3 sigma of its view depth), blended
    front to back with the early stop."""
    proj = ref.projected
    r_cw, t_cw = cam.rotation, cam.translation
    rot = quat_to_rotmat(scene.rotations.astype(np.float64))
    out = np.zeros((cam.height, cam.width, 3))
    depth_rank = np.argsort(np.argsort(proj.depth, kind="stable"), kind="stable")
    for i in range(cam.height):
        for j in range(cam.width):
            tx, ty = j // 16, i // 16
            x, y = j + 0.5, i + 0.5
            d = np.array([(x - cam.cx) / cam.fx, (y - cam.cy) / cam.fy, 1.0])
            items = []
            for k in np.flatnonzero(proj.visible):
                if not (proj.rect_min[k, 0] <= tx < proj.rect_max[k, 0]
                        and proj.rect_min[k, 1] <= ty < proj.rect_max[k, 1]):
                    continue
                a, b, c = proj.conic[k]
                dx, dy = x - proj.mean2d[k, 0], y - proj.mean2d[k, 1]
                power = -0.5 * (a * dx * dx + c * dy * dy) - b * dx * dy
                alpha = min(ALPHA_MAX, proj.opacity[k] * np.exp(power))
                if power > 0 or alpha < ALPHA_MIN:
                    continue
                mu = r_cw @ scene.means[k].astype(np.float64) + t_cw
                m = r_cw @ rot[k]
                cov = m @ np.diag(scene.scales[k].astype(np.float64) ** 2) @ m.T
                q = np.linalg.inv(cov)
                r_z = 3.0 * np.sqrt(cov[2, 2])               # t* clamped to the splat's depth range
                t = np.clip(d @ q @ mu / (d @ q @ d), mu[2] - r_z, mu[2] + r_z)
                items.append((t, depth_rank[k], alpha, proj.color[k]))
            big_t = 1.0
            for _, _, alpha, color in sorted(items, key=lambda e: e[:2]):
                if big_t * (1 - alpha) < T_MIN:
                    break
                out[i, j] += color * alpha * big_t
                big_t *= 1 - alpha
    return out


def test_per_pixel_order_equals_a_brute_force_per_pixel_sort():
    scene = random_scene(60, seed=11, spread=0.6, log_scale=(-2.2, 0.4), logit=(1.0, 1.0))
    cam = Camera.from_fov(32, 24, 60.0, look_at([0.3, -0.2, -3.0], [0, 0, 0]))
    ref = render_reference(scene, cam, PER_PIXEL, np.float64)
    glob = render_reference(scene, cam, RenderSettings(near=0.2), np.float64)
    expected = brute_force(scene, cam, ref)
    assert np.abs(ref.color - expected).max() < 1e-9
    assert np.abs(glob.color - expected).max() > 1e-3       # the order matters in this scene



def test_one_rasterizer_takes_the_order_from_its_options():
    """``rasterize`` draws either order (no second rasterizer): the same projection and tile
    lists give the per-pixel image under ``order=PER_PIXEL``, the global one otherwise; a
    projection made without the per-pixel order, or further layers, are refused."""
    from splatgl.reference import emit_keys, project, rasterize, sort, tile_ranges
    from splatgl.reference import per_pixel

    assert not hasattr(per_pixel, "rasterize_per_pixel")
    scene = random_scene(60, seed=11, spread=0.6, log_scale=(-2.2, 0.4), logit=(1.0, 1.0))
    cam = Camera.from_fov(32, 24, 60.0, look_at([0.3, -0.2, -3.0], [0, 0, 0]))
    options = ReferenceOptions(order=Order.PER_PIXEL)
    proj = project(scene, View.of(cam, PER_PIXEL, scene), PER_PIXEL, np.float64, options)
    keys, values = sort(*emit_keys(proj))
    ranges = tile_ranges(keys, proj.n_tiles)
    per = rasterize(proj, values, ranges, options=options)
    glob = rasterize(proj, values, ranges, options=ReferenceOptions())
    assert np.array_equal(per.color, render_reference(scene, cam, PER_PIXEL, np.float64).color)
    assert np.abs(per.color - glob.color).max() > 1e-3
    plain = project(scene, View.of(cam, PER_PIXEL, scene), PER_PIXEL, np.float64, ReferenceOptions())
    with pytest.raises(ValueError, match="no peak coefficients"):
        rasterize(plain, values, ranges, options=options)
    from splatgl.reference.layers import RasterLayers
    with pytest.raises(ValueError, match="no further layers"):
        rasterize(proj, values, ranges, options=options, layers=RasterLayers(median=True))


def test_window_order_known_sequences():
    pix = np.zeros(3, np.int64)
    pos = np.arange(3)
    assert window_order(pix, pos, np.array([3.0, 1.0, 2.0]), 1).tolist() == [1, 2, 0]
    assert window_order(pix, pos, np.array([3.0, 2.0, 1.0]), 1).tolist() == [1, 2, 0]
    assert window_order(pix, pos, np.array([3.0, 2.0, 1.0]), 2).tolist() == [2, 1, 0]
    # equal depths keep the list order; the window restarts at a pass boundary
    assert window_order(pix, pos, np.array([1.0, 1.0, 1.0]), 1).tolist() == [0, 1, 2]
    assert window_order(pix, np.array([0, 1, 2]), np.array([3.0, 2.0, 1.0]), 5, chunk=2).tolist() == [1, 0, 2]


def test_window_twin_is_exact_when_the_window_holds_every_splat():
    scene = random_scene(80, seed=5, spread=0.6, log_scale=(-2.2, 0.4))
    cam = Camera.from_fov(32, 32, 60.0, look_at([0.0, 0.0, -3.0], [0, 0, 0]))
    exact = render_reference(scene, cam, PER_PIXEL, np.float64)
    wide = render_reference(scene, cam, PER_PIXEL, np.float64,
                            ReferenceOptions(window=int(exact.n_blended.max()) + 80))
    narrow = render_reference(scene, cam, PER_PIXEL, np.float64, ReferenceOptions(window=1))
    assert np.array_equal(wide.color, exact.color)
    assert np.abs(narrow.color - exact.color).max() > 1e-6


def test_pass_boundary_matches_the_tile_renderer():
    from splatgl import constants

    assert TILE_LIST_CHUNK is tile_keys.TILE_LIST_CHUNK is constants.TILE_LIST_CHUNK


def crossing(angle: float) -> Scene:
    """Two flat splats crossing in an X seen from above: red tilted one way, green the other."""
    means = np.array([[0.0, 0.0, 3.0], [0.0, 0.0, 3.0 + 1e-3]])
    half = np.radians(angle) / 2
    quats = np.array([[np.cos(half), 0.0, np.sin(half), 0.0], [np.cos(-half), 0.0, np.sin(-half), 0.0]])
    scales = np.array([[0.8, 0.8, 0.01], [0.8, 0.8, 0.01]])
    colors = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    return Scene.from_activated(means, quats, scales, np.array([0.98, 0.98]),
                                ((colors - 0.5) / SH_C0)[:, None, :])


def test_crossing_splats_each_win_on_their_near_side():
    cam = Camera.from_fov(48, 32, 60.0, look_at([0, 0, 0], [0, 0, 1]))
    glob = render_reference(crossing(20), cam, RenderSettings(near=0.2), np.float64).color
    per = render_reference(crossing(20), cam, PER_PIXEL, np.float64).color
    left, right = per[16, 18], per[16, 30]
    assert glob[16, 18, 0] > glob[16, 18, 1] and glob[16, 30, 0] > glob[16, 30, 1]  # red on top
    # per pixel: the splat nearer along each ray wins, on opposite sides of the crossing
    assert (left[0] > left[1]) != (right[0] > right[1])


def test_per_pixel_refuses_lens_cameras():
    scene = random_scene(10, seed=1)
    cam = Camera.fisheye(32, 32, 180.0, look_at([0, 0, -3.0], [0, 0, 0]))
    with pytest.raises(CameraError, match="perspective and orthographic cameras, not fisheye"):
        render_reference(scene, cam, PER_PIXEL)


# ------------------------------------------------------------------ the tile renderer (GPU)
def tile_per_pixel(ctx, scene, cam, window):
    """(tile renderer's RenderOutput, the float32 twin with the same window) of one view."""
    settings = RenderSettings(near=0.2, order=Order.PER_PIXEL, order_window=window)
    renderer = TileRenderer(ctx, scene, settings)
    try:
        got = renderer.render(View.of(cam, settings, scene), with_layers(Layer.DEPTH))
    finally:
        renderer.release()
    twin = render_reference(scene, cam, settings, np.float32, ReferenceOptions(window=window))
    return got, twin


@pytest.mark.parametrize("window", [1, 4, 8])
def test_tile_renderer_per_pixel_matches_its_twin(ctx, window):
    scene = random_scene(400, seed=21, spread=0.7, log_scale=(-2.6, 0.5), logit=(1.0, 1.5))
    cam = Camera.from_fov(64, 48, 60.0, look_at([0.4, -0.3, -3.0], [0, 0, 0]))
    got, twin = tile_per_pixel(ctx, scene, cam, window)
    err = np.abs(got.rgba[..., :3] - twin.color).max()
    assert err < 1e-4, err
    assert np.abs(got.depth - twin.depth).max() < 1e-4 * np.abs(twin.depth).max()
    glob = render_reference(scene, cam, RenderSettings(near=0.2), np.float32).color
    assert np.abs(glob - twin.color).max() > 1e-2            # the order changed something


def test_tile_renderer_per_pixel_orthographic_and_surfels(ctx):
    scene = random_scene(200, seed=4, spread=0.6, log_scale=(-2.4, 0.4))
    cam = Camera.orthographic(48, 48, 20.0, look_at([0.0, 0.0, -3.0], [0, 0, 0]))
    got, twin = tile_per_pixel(ctx, scene, cam, 4)
    assert np.abs(got.rgba[..., :3] - twin.color).max() < 1e-4
    surfels = random_scene(150, seed=6, kind=SplatKind.SURFEL_2D, spread=0.6, log_scale=(-2.0, 0.3))
    cam = Camera.from_fov(48, 48, 60.0, look_at([0.3, 0.2, -3.0], [0, 0, 0]))
    got, twin = tile_per_pixel(ctx, surfels, cam, 4)
    assert np.abs(got.rgba[..., :3] - twin.color).max() < 1e-4


@pytest.mark.parametrize("ortho", [False, True])
def test_peak_coefficients_and_peak_depth_against_the_formula(ortho):
    """peak_depth(peak_coefficients(...)) is argmax_t of the 3D Gaussian along each pixel's ray
    (clamped to mu_z +- 3 sqrt(Sigma_zz)), in float64."""
    from splatgl.splatmath.peak import peak_coefficients, peak_depth

    rng = np.random.default_rng(3)
    n = 50
    pose = look_at([0.2, 0.1, -3.0], [0, 0, 0])
    cam = (Camera.orthographic(40, 30, 12.0, pose) if ortho else Camera.from_fov(40, 30, 60.0, pose))
    means = rng.normal(0, 0.5, (n, 3))
    quats = rng.normal(size=(n, 4))
    scales = np.exp(rng.uniform(-4, 0, (n, 3)))
    p_cam = means @ cam.rotation.T + cam.translation
    peak = peak_coefficients(p_cam, quats, scales, cam, np.ones(n, bool), np.float64)
    u, v = rng.uniform(0, 40, n), rng.uniform(0, 30, n)
    ax, ay = (u - cam.cx) / cam.fx, (v - cam.cy) / cam.fy
    got = peak_depth(peak, ax, ay, ortho)
    rot = quat_to_rotmat(quats / np.linalg.norm(quats, axis=1, keepdims=True))
    for k in range(n):
        m = cam.rotation @ rot[k]
        cov = m @ np.diag(scales[k] ** 2) @ m.T
        q = np.linalg.inv(cov)
        origin, d = (np.array([ax[k], ay[k], 0.0]), np.array([0.0, 0, 1])) if ortho else \
            (np.zeros(3), np.array([ax[k], ay[k], 1.0]))
        t = d @ q @ (p_cam[k] - origin) / (d @ q @ d)
        r_z = 3 * np.sqrt(cov[2, 2])
        assert got[k] == pytest.approx(np.clip(t, p_cam[k, 2] - r_z, p_cam[k, 2] + r_z), rel=1e-8, abs=1e-9)


def test_cli_order_per_pixel(tmp_path, capsys):
    from splatgl.cli import main

    size = ["--width", "48", "--height", "32"]
    assert main(["render", "--renderer", "tile", "--order", "per-pixel", "--order-window", "4",
                 "-o", str(tmp_path / "t.png")] + size) == 0
    assert main(["render", "--renderer", "reference", "--order", "per-pixel",
                 "--emulate", "sort=bucket16", "-o", str(tmp_path / "r.png")] + size) == 0
    capsys.readouterr()
    assert main(["render", "--order", "per-pixel", "-o", str(tmp_path / "q.png")] + size) == 2
    assert "--order per-pixel is drawn by the tile renderer and the NumPy reference" in capsys.readouterr().err
    assert main(["render", "--emulate", "extent=fixed", "-o", str(tmp_path / "q.png")] + size) == 2
    assert "--emulate extent=fixed applies to the NumPy reference only" in capsys.readouterr().err
    assert main(["render", "--renderer", "tile", "--order", "per-pixel", "--order-window", "33",
                 "-o", str(tmp_path / "q.png")] + size) == 2
    assert "must be 1..32, got 33" in capsys.readouterr().err
    assert not (tmp_path / "q.png").exists()
