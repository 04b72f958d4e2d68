"""Property tests of the NumPy reference rasterizer (hypothesis, derandomised; fast)."""

from __future__ import annotations

import math

import numpy as np
from hypothesis import given, settings as hsettings, strategies as st

from splatgl.cameras.camera import Camera
from splatgl.constants import (ALPHA_MAX, ALPHA_MIN, EXTENT_DISCRIMINANT_FLOOR, LOW_PASS, SH_C0,
                               T_MIN)
from splatgl.reference import (gaussian_alpha, gaussian_power, rasterize, render_reference,
                               transmittance_trace)
from splatgl.scene.splats import Scene
from splatgl.scene.settings import RenderSettings

from helpers import IN_VIEW, random_scene

FAST = hsettings(max_examples=25)
unit = st.floats(0.0, 1.0)


def splats_at(xyz, scale: float, opacity: float, colors) -> Scene:
    """Isotropic unrotated splats at camera-space ``xyz`` (identity pose) with DC colours."""
    xyz = np.asarray(xyz, np.float64)
    n = xyz.shape[0]
    sh = ((np.asarray(colors, np.float64) - 0.5) / SH_C0).reshape(n, 1, 3)
    return Scene.from_activated(xyz, np.tile([1.0, 0, 0, 0], (n, 1)), np.full((n, 3), scale),
                                np.full(n, opacity), sh)


def square_rect_mask(u: float, v: float, var: float, width: int, height: int) -> np.ndarray:
    """(H, W) pixels inside the INRIA tile rectangle of an isotropic splat of variance ``var``."""
    r = math.ceil(3.0 * math.sqrt(var + math.sqrt(EXTENT_DISCRIMINANT_FLOOR)))
    gw, gh = -(-width // 16), -(-height // 16)

    def span(p: float, grid: int) -> tuple[int, int]:
        lo = min(grid, max(0, int((p - 0.5 - r) / 16)))
        hi = min(grid, max(0, int((p - 0.5 + r + 15) / 16)))
        return 16 * lo, 16 * hi

    (x0, x1), (y0, y1) = span(u, gw), span(v, gh)
    mask = np.zeros((height, width), bool)
    mask[y0:y1, x0:x1] = True
    return mask


def isotropic_alpha(u, v, var, o, width, height) -> np.ndarray:
    """Closed form ``o exp(-r^2 / (2 var))`` at pixel centres with the reference's cut, clamp, rect."""
    jj, ii = np.meshgrid(np.arange(width) + 0.5, np.arange(height) + 0.5)
    alpha = np.minimum(ALPHA_MAX, o * np.exp(-((jj - u) ** 2 + (ii - v) ** 2) / (2.0 * var)))
    alpha[alpha < ALPHA_MIN] = 0.0
    return np.where(square_rect_mask(u, v, var, width, height), alpha, 0.0)


# --------------------------------------------------------------------------------- properties
@FAST
@given(bg=st.tuples(unit, unit, unit), empty=st.booleans(), f64=st.booleans())
def test_empty_or_culled_scene_is_exactly_background(bg, empty, f64):
    dtype = np.float64 if f64 else np.float32
    if empty:
        scene = splats_at(np.zeros((0, 3)), 0.1, 0.5, np.zeros((0, 3)))
    else:   # behind the camera, at the near plane, and far off screen
        scene = splats_at([[0, 0, -1.0], [0, 0, 0.1], [50.0, 0, 2.0]], 0.1, 0.9, np.ones((3, 3)))
    cam = Camera(37, 21, 30.0, 30.0, 18.0, 10.0)
    img = render_reference(scene, cam, RenderSettings(background=bg, near=0.2), dtype)
    np.testing.assert_array_equal(img.color, np.broadcast_to(np.asarray(bg, dtype), (21, 37, 3)))
    assert not img.alpha.any() and not img.depth.any() and not img.n_contrib.any()


@FAST
@given(a=st.floats(1e-4, 10.0), c=st.floats(1e-4, 10.0), rho=st.floats(-0.999, 0.999),
       o=unit, dx=st.floats(-50, 50), dy=st.floats(-50, 50))
def test_alpha_is_zero_or_in_cut_range(a, c, rho, o, dx, dy):
    conic = np.array([a, rho * math.sqrt(a * c), c])
    alpha = gaussian_alpha(gaussian_power(conic, np.float64(dx), np.float64(dy)), np.float64(o),
                           ALPHA_MAX)
    assert alpha == 0.0 or ALPHA_MIN <= alpha <= ALPHA_MAX


@FAST
@given(seed=st.integers(0, 10_000))
def test_transmittance_never_increases_along_a_tile_list(seed):
    scene = random_scene(200, seed, degree=1, **IN_VIEW)
    cam = Camera(48, 40, 45.0, 45.0, 24.0, 20.0)
    img = render_reference(scene, cam, RenderSettings(near=0.2), np.float64)
    final = img.transmittance
    for tile in np.flatnonzero(img.ranges[:, 1] > img.ranges[:, 0]):
        trace = transmittance_trace(img.projected, img.sorted_values, img.ranges, tile)
        steps = trace[1:] / trace[:-1]
        assert np.all(np.diff(trace, axis=0) <= 0) and trace.min() >= T_MIN
        assert steps.min() >= 1.0 - ALPHA_MAX - 1e-12       # every blended alpha <= 0.99
        ty, tx = divmod(int(tile), img.projected.grid[0])
        block = final[16 * ty:16 * ty + 16, 16 * tx:16 * tx + 16]
        np.testing.assert_array_equal(trace[-1].reshape(16, 16)[:block.shape[0], :block.shape[1]],
                                      block)


@FAST
@given(s=st.floats(0.005, 0.3), z=st.floats(0.5, 8.0), o=st.floats(0.01, 1.0),
       du=st.floats(-20.0, 20.0), dv=st.floats(-20.0, 20.0), bg=st.tuples(unit, unit, unit))
def test_single_isotropic_gaussian_matches_closed_form(s, z, o, du, dv, bg):
    width, height, f = 61, 47, 70.0
    cam = Camera(width, height, f, f, 30.5 + du, 23.5 + dv)   # splat on the axis -> at (cx, cy)
    scene = splats_at([[0.0, 0.0, z]], s, o, [[0.9, 0.4, 0.1]])
    img = render_reference(scene, cam, RenderSettings(background=bg, near=0.2), np.float64)
    z32 = float(scene.means[0, 2])
    var = (f * float(scene.scales[0, 0]) / z32) ** 2 + LOW_PASS
    alpha = isotropic_alpha(cam.cx, cam.cy, var, float(scene.opacities[0]), width, height)
    color = SH_C0 * scene.sh[0, 0].astype(np.float64) + 0.5
    np.testing.assert_allclose(img.alpha, alpha, atol=1e-6)
    np.testing.assert_allclose(img.color, alpha[..., None] * color
                               + (1 - alpha[..., None]) * np.asarray(bg), atol=1e-6)
    np.testing.assert_allclose(img.depth, z32 * alpha, atol=1e-6)


@FAST
@given(seed=st.integers(0, 10_000), perm_seed=st.integers(0, 10_000))
def test_input_order_does_not_matter(seed, perm_seed):
    scene = random_scene(150, seed, degree=1, **IN_VIEW)
    cam = Camera(50, 38, 45.0, 45.0, 25.0, 19.0)
    perm = np.random.default_rng(perm_seed).permutation(scene.count)
    settings = RenderSettings(background=(0.1, 0.2, 0.3), near=0.2)
    a = render_reference(scene, cam, settings, np.float32)
    b = render_reference(scene.subset(perm), cam, settings, np.float32)
    np.testing.assert_array_equal(a.color, b.color)
    np.testing.assert_array_equal(a.n_contrib, b.n_contrib)


def test_float32_and_float64_agree():
    cam = Camera(64, 48, 55.0, 55.0, 32.0, 24.0)
    settings = RenderSettings(background=(0.3, 0.3, 0.3), near=0.2)
    for seed in range(4):
        scene = random_scene(300, seed, degree=1, **IN_VIEW)
        a = render_reference(scene, cam, settings, np.float32)
        b = render_reference(scene, cam, settings, np.float64)
        assert a.color.dtype == np.float32 and b.color.dtype == np.float64
        np.testing.assert_allclose(a.color, b.color, atol=1e-5)
        np.testing.assert_allclose(a.alpha, b.alpha, atol=1e-5)


@FAST
@given(n=st.integers(1, 40), o=st.floats(0.3, 1.0), s=st.floats(0.05, 0.5),
       x=st.floats(-0.3, 0.3), y=st.floats(-0.3, 0.3), seed=st.integers(0, 100))
def test_early_stop_matches_formula(n, o, s, x, y, seed):
    """n identical footprints (orthographic: size independent of z) at distinct depths."""
    width, height, ppu = 40, 36, 30.0
    cam = Camera.orthographic(width, height, ppu)
    rng = np.random.default_rng(seed)
    z = 1.0 + np.arange(n) * 0.25
    colors = rng.uniform(0.0, 1.0, (n, 3))
    order = rng.permutation(n)
    scene = splats_at(np.stack([np.full(n, x), np.full(n, y), z], 1)[order], s, o, colors[order])
    img = render_reference(scene, cam, RenderSettings(near=0.2), np.float64)

    var = (ppu * float(scene.scales[0, 0])) ** 2 + LOW_PASS
    u, v = ppu * float(scene.means[0, 0]) + width / 2, ppu * float(scene.means[0, 1]) + height / 2
    a = isotropic_alpha(u, v, var, float(scene.opacities[0]), width, height)
    sh_colors = SH_C0 * scene.sh[np.argsort(order), 0].astype(np.float64) + 0.5
    t, c = np.ones_like(a), np.zeros(a.shape + (3,))
    depth, used, live = np.zeros_like(a), np.zeros(a.shape, np.int64), a > 0
    for k in range(n):
        nxt = t * (1.0 - a)
        live &= nxt >= T_MIN
        w = np.where(live, a * t, 0.0)
        c += w[..., None] * sh_colors[k]
        depth += w * float(scene.means[np.argsort(order)[k], 2])
        used = np.where(live, k + 1, used)
        t = np.where(live, nxt, t)
    np.testing.assert_allclose(img.color, c, atol=1e-12)
    np.testing.assert_allclose(img.transmittance, t, atol=1e-12)
    np.testing.assert_allclose(img.depth, depth, atol=1e-10)
    np.testing.assert_array_equal(img.n_contrib, used)
    if n >= 20 and o >= 0.9:                        # the early stop really happened
        assert (used < n).any()


def test_opaque_stack_stops_after_two_layers():
    """alpha = 0.99 everywhere near the centre: T = 0.01 after one layer, 1e-4 after two (kept,
    since 0.01^2 in float64 is just above 1e-4), the third would give 1e-6 and stops."""
    cam = Camera.orthographic(16, 16, 4.0)
    scene = splats_at([[0, 0, 1.0], [0, 0, 2.0], [0, 0, 3.0], [0, 0, 4.0]], 20.0, 1.0,
                      [[1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 1]])
    img = render_reference(scene, cam, RenderSettings(near=0.2), np.float64)
    t2 = (1 - ALPHA_MAX) ** 2
    assert t2 >= T_MIN
    centre = img.color[8, 8]
    alpha_c = 1 - img.transmittance[8, 8]
    assert img.n_contrib[8, 8] == 2
    assert abs(alpha_c - (1 - t2)) < 1e-12
    np.testing.assert_allclose(centre, [ALPHA_MAX, ALPHA_MAX * (1 - ALPHA_MAX), 0], atol=1e-6)
    r = rasterize(img.projected, img.sorted_values, img.ranges, chunk=1)
    np.testing.assert_array_equal(r.n_contrib, img.n_contrib)
