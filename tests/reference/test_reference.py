"""Stage-by-stage tests of the NumPy per-tile reference rasterizer (splatgl.reference)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from splatgl.cameras.camera import Camera
from splatgl.constants import ALPHA_MIN, LOW_PASS, SH_C0, T_MIN
from splatgl.splatmath.project import antialias_factor
from splatgl.reference import (Compat, ProjectedSplats, ReferenceOptions, depth_bits, emit_keys,
                               gsplat_radius, rasterize, render_reference, sort, tile_ranges)
from splatgl.scene.splats import Scene, SplatKind
from splatgl.scene.settings import RenderSettings
from helpers import project

from helpers import IN_VIEW, random_scene

NEAR = RenderSettings(near=0.2)


def scene_of(means, scale=0.05, opacity=0.8, color=(1.0, 0.5, 0.25)) -> Scene:
    """Scene of isotropic, unrotated splats with one DC colour."""
    means = np.atleast_2d(np.asarray(means, np.float64))
    n = means.shape[0]
    quats = np.tile([1.0, 0.0, 0.0, 0.0], (n, 1))
    scales = np.broadcast_to(np.asarray(scale, np.float64).reshape(-1, 1), (n, 3))
    opac = np.broadcast_to(np.asarray(opacity, np.float64), (n,))
    sh = np.tile(((np.asarray(color) - 0.5) / SH_C0)[None, None, :], (n, 1, 1))
    return Scene.from_activated(means, quats, scales, opac, sh)


def oracle(proj: ProjectedSplats, values, ranges, background, options=ReferenceOptions()):
    """Literal per-pixel transcription of 3DGS's renderCUDA (slow; small images only)."""
    h, w = proj.height, proj.width
    gw = proj.grid[0]
    amax = options.resolved_alpha_max
    color = np.zeros((h, w, 3))
    trans = np.ones((h, w))
    n_contrib = np.zeros((h, w), np.int64)
    for i in range(h):
        for j in range(w):
            tile = (i // 16) * gw + j // 16
            t, c, last = 1.0, np.zeros(3), 0
            for k, pos in enumerate(range(ranges[tile, 0], ranges[tile, 1])):
                s = values[pos]
                dx, dy = j + 0.5 - proj.mean2d[s, 0], i + 0.5 - proj.mean2d[s, 1]
                a, b, cc = proj.conic[s]
                power = -0.5 * (a * dx * dx + cc * dy * dy) - b * dx * dy
                if power > 0:
                    continue
                alpha = min(amax, proj.opacity[s] * math.exp(power))
                if alpha < ALPHA_MIN:
                    continue
                test_t = t * (1 - alpha)
                if test_t < T_MIN or (options.stop_inclusive and test_t <= T_MIN):
                    break
                c = c + proj.color[s] * alpha * t
                t, last = test_t, k + 1
            color[i, j] = c + t * np.asarray(background)
            trans[i, j], n_contrib[i, j] = t, last
    return color, trans, n_contrib


# ------------------------------------------------------------------------------------ project
def test_project_single_splat_matches_hand_values():
    cam = Camera(64, 48, 100.0, 100.0, 32.0, 24.0)
    proj = project(scene_of([[0.3, -0.2, 4.0]]), cam, NEAR, np.float64)
    assert proj.visible.tolist() == [True]
    np.testing.assert_allclose(proj.mean2d[0], [39.5, 19.0], atol=1e-5)
    assert proj.grid == (4, 3)
    assert proj.radius[0].tolist() == [5, 5]            # ceil(3 sqrt(2.185...))
    assert proj.rect_min[0].tolist() == [2, 0]          # (int)((39 - 5) / 16), (int)((18.5 - 5) / 16)
    assert proj.rect_max[0].tolist() == [3, 2]          # (int)((39 + 20) / 16), (int)((18.5 + 20) / 16)
    np.testing.assert_allclose(proj.color[0], [1.0, 0.5, 0.25], atol=1e-6)
    np.testing.assert_allclose(proj.opacity[0], 0.8, atol=1e-6)
    assert proj.depth[0] == pytest.approx(4.0)


def test_project_rect_uses_3dgs_pixel_index_coordinates():
    # u = 21 is p = 20.5 in 3DGS's coordinates: (int)((20.5 - r) / 16) with r = 5 is 0, not 1.
    cam = Camera(64, 48, 100.0, 100.0, 32.0, 24.0)
    z = 4.0
    proj = project(scene_of([[(21.0 - 32.0) * z / 100.0, 0.0, z]]), cam, NEAR, np.float64)
    r = int(proj.radius[0, 0])
    assert r == 5
    assert proj.rect_min[0, 0] == int((21.0 - 0.5 - r) / 16) == 0
    assert proj.rect_max[0, 0] == int((21.0 - 0.5 + r + 15) / 16) == 2


@pytest.mark.parametrize("z, visible", [(0.125, False), (0.25, False), (0.2501, True), (-3.0, False)])
def test_project_culls_at_or_before_near_plane(z, visible):
    cam = Camera(64, 48, 100.0, 100.0, 32.0, 24.0)
    settings = RenderSettings(near=0.25)                # exactly representable in float32
    proj = project(scene_of([[0.0, 0.0, z]], scale=0.001), cam, settings, np.float64)
    assert proj.visible[0] == visible
    if not visible:
        assert proj.tiles_touched[0] == 0 and proj.radius[0].tolist() == [0, 0]


def test_project_culls_off_screen_splats():
    cam = Camera(64, 48, 100.0, 100.0, 32.0, 24.0)
    proj = project(scene_of([[5.0, 0.0, 4.0], [0.0, 0.0, 4.0]], scale=0.01), cam, NEAR)
    assert proj.visible.tolist() == [False, True]


def test_project_antialias_scales_opacity():
    cam = Camera(64, 48, 100.0, 100.0, 32.0, 24.0)
    scene = scene_of([[0.1, 0.1, 3.0]], scale=0.004, opacity=0.9)
    plain = project(scene, cam, NEAR, np.float64)
    aa = project(scene, cam, RenderSettings(near=0.2, antialias=True), np.float64)
    cov = np.linalg.inv(np.array([[plain.conic[0, 0], plain.conic[0, 1]],
                                  [plain.conic[0, 1], plain.conic[0, 2]]]))
    assert aa.opacity[0] == pytest.approx(plain.opacity[0] * antialias_factor(cov[None])[0], rel=1e-9)
    assert aa.opacity[0] < plain.opacity[0]


def test_project_orthographic_footprint_is_depth_independent():
    cam = Camera.orthographic(64, 48, 40.0)
    proj = project(scene_of([[0.2, 0.1, 1.0], [0.2, 0.1, 9.0]], scale=0.05), cam, NEAR, np.float64)
    np.testing.assert_allclose(proj.mean2d, [[40.0, 28.0], [40.0, 28.0]], atol=1e-5)
    v = (40.0 * np.float32(0.05)) ** 2 + LOW_PASS
    np.testing.assert_allclose(proj.conic, [[1 / v, 0, 1 / v]] * 2, rtol=1e-6, atol=1e-12)


def test_surfels_are_projected_and_near_culled():
    """2DGS surfels take the surfel branch (tests/renderers/test_surfels.py); one at z = 0 is near-culled."""
    scene = Scene(np.zeros((1, 3)), np.array([[1.0, 0, 0, 0]]), np.zeros((1, 2)), np.zeros(1),
                  np.zeros((1, 1, 3)), SplatKind.SURFEL_2D)
    ref = render_reference(scene, Camera(16, 16, 10.0, 10.0, 8.0, 8.0), NEAR)
    assert ref.projected.is_surfel and not ref.projected.visible[0]
    assert np.all(ref.alpha == 0.0)


def test_project_rejects_other_dtypes():
    with pytest.raises(ValueError, match="float32 or float64"):
        project(scene_of([[0, 0, 2.0]]), Camera(16, 16, 10.0, 10.0, 8.0, 8.0), NEAR, np.float16)


# ------------------------------------------------------------------------------------ gsplat
def test_gsplat_radius_is_per_axis_and_opacity_aware():
    cov = np.array([[[4.0, 1.0], [1.0, 9.0]]] * 3)
    opac = np.array([0.5, 1.0, 0.003])
    k = math.sqrt(2 * math.log(0.5 * 255))                     # 3.115 < 3.33
    expect = [[math.ceil(k * 2), math.ceil(k * 3)], [math.ceil(3.33 * 2), math.ceil(3.33 * 3)], [0, 0]]
    assert gsplat_radius(cov, opac).tolist() == expect == [[7, 10], [7, 10], [0, 0]]


def test_gsplat_rect_and_alpha_clamp():
    cam = Camera(64, 48, 100.0, 100.0, 32.0, 24.0)
    scene = scene_of([[0.0, 0.0, 4.0]], scale=1.0, opacity=1.0)   # 25 px: flat near the centre
    g = project(scene, cam, NEAR, np.float64, ReferenceOptions(Compat.GSPLAT))
    r = g.radius[0]
    assert r[0] == r[1] == math.ceil(3.33 * math.sqrt(625.0 + LOW_PASS)) == 84
    assert g.rect_min[0].tolist() == [max(0, math.floor((32 - r[0]) / 16)), 0]
    assert g.rect_max[0].tolist() == [min(4, math.ceil((32 + r[0]) / 16)), 3]
    centre = (slice(23, 25), slice(31, 33))
    for compat, amax in [(Compat.INRIA, 0.99), (Compat.GSPLAT, 0.999),
                         (ReferenceOptions(Compat.GSPLAT, alpha_max=0.5), 0.5)]:
        img = render_reference(scene, cam, NEAR, np.float64, compat)
        np.testing.assert_allclose(img.alpha[centre], amax, atol=1e-12)


def test_gsplat_matches_oracle():
    scene = random_scene(120, 3, degree=1, **IN_VIEW)
    cam = Camera(40, 35, 45.0, 45.0, 20.0, 17.0)
    opts = ReferenceOptions(Compat.GSPLAT)
    img = render_reference(scene, cam, NEAR, np.float64, opts)
    color, trans, n = oracle(img.projected, img.sorted_values, img.ranges, (0, 0, 0), opts)
    np.testing.assert_allclose(img.color, color, atol=1e-12)
    np.testing.assert_array_equal(img.n_contrib, n)


# ------------------------------------------------------------------------------------ binning
def hand_projection() -> ProjectedSplats:
    """Three splats on a 3 x 2 tile grid; splat 2 is culled."""
    z = np.array([2.0, 1.5, 1.0])
    return ProjectedSplats(
        visible=np.array([True, True, False]), depth=z, mean2d=np.zeros((3, 2)),
        conic=np.zeros((3, 3)), opacity=np.zeros(3), color=np.zeros((3, 3)),
        radius=np.zeros((3, 2), np.int64),
        rect_min=np.array([[0, 1], [1, 0], [0, 0]]), rect_max=np.array([[2, 2], [2, 2], [0, 0]]),
        width=48, height=32, grid=(3, 2))


def test_emit_keys_hand_made():
    keys, idx = emit_keys(hand_projection())
    bits = [int(np.float32(v).view(np.uint32)) for v in (2.0, 1.5)]
    # splat 0 covers tiles (x, y) = (0, 1), (1, 1) -> ids 3, 4; splat 1 covers (1, 0), (1, 1) -> 1, 4
    assert keys.dtype == np.uint64 and idx.tolist() == [0, 0, 1, 1]
    assert keys.tolist() == [(3 << 32) | bits[0], (4 << 32) | bits[0], (1 << 32) | bits[1],
                             (4 << 32) | bits[1]]
    assert depth_bits(np.array([2.0])).tolist() == [0x40000000]


def test_sort_orders_by_tile_then_depth():
    keys, idx = sort(*emit_keys(hand_projection()))
    assert idx.tolist() == [1, 0, 1, 0]           # tile 1: s1; tile 3: s0; tile 4: s1 (1.5) < s0 (2.0)
    assert np.all(np.diff(keys.astype(np.float64)) >= 0)


def test_sort_is_stable_on_ties():
    keys = np.array([5, 3, 5, 3, 3, 1 << 40, 5], np.uint64)
    sk, sv = sort(keys, np.arange(7))
    assert sv.tolist() == [1, 3, 4, 0, 2, 6, 5]
    assert sk.tolist() == sorted(keys.tolist())


def test_tile_ranges_hand_made():
    keys = (np.array([0, 0, 2, 2, 2, 3], np.uint64) << np.uint64(32)) | np.uint64(7)
    assert tile_ranges(keys, 5).tolist() == [[0, 2], [2, 2], [2, 5], [5, 6], [6, 6]]
    assert tile_ranges(np.zeros(0, np.uint64), 2).tolist() == [[0, 0], [0, 0]]


# ------------------------------------------------------------------------------------ rasterize
@pytest.mark.parametrize("seed, dtype", [(0, np.float64), (1, np.float64), (2, np.float32)])
def test_rasterize_matches_serial_oracle(seed, dtype):
    scene = random_scene(150, seed, degree=1, **IN_VIEW)
    cam = Camera(45, 37, 50.0, 50.0, 23.0, 17.5)         # partial tiles on both edges
    bg = (0.2, 0.3, 0.4)
    img = render_reference(scene, cam, RenderSettings(background=bg, near=0.2), dtype)
    color, trans, n = oracle(img.projected, img.sorted_values, img.ranges, bg)
    tol = 1e-12 if dtype == np.float64 else 1e-5
    np.testing.assert_allclose(img.color, color, atol=tol)
    np.testing.assert_allclose(img.transmittance, trans, atol=tol)
    if dtype == np.float64:
        np.testing.assert_array_equal(img.n_contrib, n)
    assert img.n_contrib.max() > 10 and img.alpha.max() > 0.9


def test_rasterize_does_not_depend_on_vectorisation_knobs():
    scene = random_scene(400, 5, degree=1, **IN_VIEW)
    cam = Camera(70, 50, 60.0, 60.0, 35.0, 25.0)
    img = render_reference(scene, cam, NEAR, np.float32)
    for chunk, batch, workers in [(1, 1, 1), (5, 3, 2), (1000, 100, 1)]:
        r = rasterize(img.projected, img.sorted_values, img.ranges, (0, 0, 0), chunk=chunk,
                      tiles_per_batch=batch, workers=workers)
        np.testing.assert_array_equal(r.transmittance, img.transmittance)
        np.testing.assert_array_equal(r.n_contrib, img.n_contrib)
        np.testing.assert_allclose(r.color, img.color, atol=2e-6)


def test_rgba_is_float32_with_row_zero_on_top():
    cam = Camera(32, 64, 80.0, 80.0, 16.0, 32.0)
    scene = scene_of([[0.0, -1.2, 4.0]], scale=0.05)    # v = 32 - 24 = 8: near the top
    rgba = render_reference(scene, cam, RenderSettings(near=0.2, background=(0, 0, 1))).rgba
    assert rgba.shape == (64, 32, 4) and rgba.dtype == np.float32
    assert rgba[:16, :, 3].max() > 0.5 and rgba[32:, :, 3].max() == 0.0
    np.testing.assert_array_equal(rgba[40, 0], [0, 0, 1, 0])


def test_depth_is_alpha_weighted_view_z():
    cam = Camera(32, 32, 50.0, 50.0, 16.0, 16.0)
    img = render_reference(scene_of([[0.0, 0.0, 3.0]], scale=0.1), cam, NEAR, np.float64)
    np.testing.assert_allclose(img.depth, 3.0 * img.alpha, atol=1e-6)
