"""The reference's emulation knobs (splatgl/scene/emulation.py): each changes the reference in
the documented way, and only that way."""

from __future__ import annotations

import math

import numpy as np
import pytest

from splatgl.cameras.camera import Camera
from splatgl.constants import ALPHA_MIN, LOW_PASS, SH_C0
from splatgl.errors import SplatglError
from splatgl.scene.emulation import Emulation, parse_emulation, parse_knob
from splatgl.reference.emulation import quad_emulation
from splatgl.scene.splats import Scene
from splatgl.scene.settings import GpuStorage, QuadExtent, RenderSettings, SortKey
from splatgl.reference import ReferenceOptions, project, render_reference
from splatgl.splatmath.project import reference_radius
from splatgl.cameras.view import View

W = H = 64
CAM = Camera(W, H, 64.0, 64.0, 32.5, 32.5)   # the centre splat lands on pixel (32, 32)


def splats(means, scales, opacities, colors=None, sh_rest=None) -> Scene:
    """Axis-aligned splats (identity rotation) with activated values."""
    n = len(means)
    colors = np.full((n, 3), 0.5) if colors is None else np.asarray(colors, float)
    sh = ((colors - 0.5) / SH_C0)[:, None, :]
    if sh_rest is not None:
        sh = np.concatenate([sh, sh_rest], 1)
    scales = np.broadcast_to(np.asarray(scales, float).reshape(n, -1), (n, 3))
    return Scene.from_activated(np.asarray(means, float), np.tile([1.0, 0, 0, 0], (n, 1)),
                                scales, np.asarray(opacities, float), sh)


def draw(scene, **knobs):
    em = Emulation(**knobs)
    return render_reference(scene, CAM, RenderSettings(near=0.2, emulation=em), np.float64)


def pixel_alpha(scene, x, y, **knobs) -> float:
    return float(draw(scene, **knobs).alpha[y, x])


# One isotropic splat at the image centre, sigma_screen = 64 * 0.05 = 3.2 px (about 3.25 with
# the low pass), opacity 1.
ONE = splats([[0.0, 0.0, 1.0]], 0.05, [1.0])
SIGMA = math.sqrt((64 * 0.05) ** 2 + LOW_PASS)


def q_at(dx, dy):
    """q at a pixel (dx, dy) pixels from the centre splat's."""
    return (dx * dx + dy * dy) / SIGMA ** 2


def test_default_emulation_is_the_reference():
    plain = render_reference(ONE, CAM, RenderSettings(near=0.2), np.float64)
    assert np.array_equal(draw(ONE).color, plain.color)
    assert Emulation().is_default and Emulation().label() == "reference"


def test_extent_fixed_cuts_the_ellipse_at_sqrt8_sigma():
    inside, outside = 9, 10          # q 7.7 and 9.5
    assert q_at(inside, 0) < 8 < q_at(outside, 0)
    for dx in (inside, outside):
        base = pixel_alpha(ONE, 32 + dx, 32)
        fixed = pixel_alpha(ONE, 32 + dx, 32, extent="fixed")
        assert base > ALPHA_MIN
        assert fixed == (base if dx == inside else 0.0)


def test_extent_fixed_quad_is_the_square_along_the_axes():
    # Diagonal at about 2.2 sigma per axis: outside sqrt(8) radially, inside the +-2.83 square.
    d = round(2.2 * SIGMA)
    assert q_at(d, d) > 8 and d / SIGMA < 2.83
    assert pixel_alpha(ONE, 32 + d, 32 + d, extent="fixed") == 0.0
    assert pixel_alpha(ONE, 32 + d, 32 + d, extent="fixed-quad") == pytest.approx(
        math.exp(-0.5 * q_at(d, d)), rel=1e-5)  # float32 storage
    # Along x at 3 sigma: inside the ellipse's alpha range, outside the quad.
    e = round(3.0 * SIGMA)
    assert e / SIGMA > 2.83
    assert pixel_alpha(ONE, 32 + e, 32, extent="fixed-quad") == 0.0
    assert pixel_alpha(ONE, 32 + e, 32, extent="opacity") > ALPHA_MIN


def test_extent_square_and_opacity_against_the_3_sigma_radius():
    scale = 0.06075                          # sigma 3.93 px; radius ceil(3 sqrt(lam_max)) = 12
    sigma = math.sqrt((64 * scale) ** 2 + LOW_PASS)
    scene = splats([[0.0, 0.0, 1.0]], scale, [1.0])
    r = int(reference_radius(np.diag([sigma ** 2, sigma ** 2])[None])[0])  # 0.1 floor inside
    assert r == 12
    x = 32 + r + 1                           # a pixel centre r + 1 from the mean: outside
    alpha = math.exp(-0.5 * ((r + 1) / sigma) ** 2)
    assert alpha > ALPHA_MIN
    assert pixel_alpha(scene, x, 32, extent="square") == 0.0
    assert pixel_alpha(scene, x, 32, extent="opacity") == pytest.approx(alpha, rel=1e-5)
    assert pixel_alpha(scene, x - 1, 32, extent="square") > 0.0


def test_min_alpha_skips_faint_fragments():
    d = 10                                   # alpha about 0.009 at (32 + d, 32)
    base = pixel_alpha(ONE, 32 + d, 32, extent="opacity")
    assert ALPHA_MIN < base < 0.01
    assert pixel_alpha(ONE, 32 + d, 32, extent="opacity", min_alpha=0.01) == 0.0
    assert pixel_alpha(ONE, 32, 32, min_alpha=0.01) == pytest.approx(0.99)


def test_alpha_max_clamp():
    assert pixel_alpha(ONE, 32, 32) == pytest.approx(0.99)
    assert pixel_alpha(ONE, 32, 32, alpha_max=0.999) == pytest.approx(0.999, rel=1e-6)
    assert ReferenceOptions(emulation=Emulation(alpha_max=0.9)).resolved_alpha_max == 0.9


def proj(scene, **knobs):
    options = ReferenceOptions(emulation=Emulation(**knobs))
    settings = RenderSettings(near=0.2)
    return project(scene, View.of(CAM, settings, scene), settings, np.float64, options)


def test_low_pass_and_compensation():
    sigma2 = (64 * 0.05) ** 2
    for lp in (LOW_PASS, 0.1):
        p = proj(ONE, low_pass=lp)
        assert p.conic[0, 0] == pytest.approx(1.0 / (sigma2 + lp), rel=1e-6)  # float32 storage
    p = proj(ONE, low_pass=0.1, compensation=True)
    assert p.opacity[0] == pytest.approx(math.sqrt(sigma2 ** 2 / (sigma2 + 0.1) ** 2), rel=1e-6)
    assert proj(ONE, compensation=False).opacity[0] == 1.0


def test_sh_cap():
    rest = np.zeros((1, 3, 3))
    rest[0, 1, :] = 1.0                     # degree-1 z term: colour changes with the view
    scene = splats([[0.0, 0.0, 1.0]], 0.05, [1.0], [[0.2, 0.4, 0.6]], rest)
    assert not np.allclose(proj(scene).color[0], [0.2, 0.4, 0.6])
    assert np.allclose(proj(scene, sh=0).color[0], [0.2, 0.4, 0.6])


def test_half_rounds_positions_and_scales():
    scene = splats([[0.01234, 0.0, 1.0]], 0.0512345, [1.0])
    rounded = splats([[float(np.float16(0.01234)), 0.0, 1.0]],
                     float(np.float16(scene.scales[0, 0])), [1.0])
    half, plain, expected = proj(scene, half=True), proj(scene), proj(rounded)
    assert half.mean2d[0, 0] == expected.mean2d[0, 0] != plain.mean2d[0, 0]
    assert half.conic[0, 0] == pytest.approx(expected.conic[0, 0], rel=1e-6)
    assert abs(half.conic[0, 0] / plain.conic[0, 0] - 1) > 1e-4


def order_of(scene, **knobs):
    ref = draw(scene, **knobs)
    tile = (32 // 16) * (W // 16) + 32 // 16
    start, end = ref.ranges[tile]
    return [int(v) for v in ref.sorted_values[start:end]]


def test_depth_distance_orders_by_distance():
    # 0: off axis, z 2.0 but distance 2.06; 1: on axis at z 2.03 (nearer by distance).
    scene = splats([[0.5, 0.0, 2.0], [0.0, 0.0, 2.03]], [0.3, 0.3], [0.5, 0.5])
    assert order_of(scene) == [0, 1]
    assert order_of(scene, depth="distance") == [1, 0]
    assert order_of(scene, depth="z") == [0, 1]


def test_sort_bucket16_ties_close_splats_when_depths_spread():
    # 1 is in front of 0 by 1e-4; a splat 1e3 away makes a bucket 0.015 deep, so they tie and
    # keep index order; exactly, 1 comes first.
    scene = splats([[0.0, 0.0, 2.0001], [0.0, 0.0, 2.0], [0.0, 0.0, 1000.0]],
                   [0.3, 0.3, 30.0], [0.5, 0.5, 0.5])
    assert order_of(scene)[:2] == [1, 0]
    assert order_of(scene, sort="bucket16")[:2] == [0, 1]


def test_parse_knobs_and_errors():
    em = parse_emulation(["sort=bucket16", "extent=fixed", "min-alpha=1/255", "sh=2",
                          "half=on", "compensation=off", "alpha_max=0.999", "depth=distance",
                          "low_pass=0.1"])
    assert em == Emulation("bucket16", "fixed", ALPHA_MIN, 0.1, False, 2, True, 0.999, "distance")
    assert "extent=fixed" in em.label() and "half=on" in em.label()
    for bad, words in [("extent", "KNOB=VALUE"), ("colour=1", "unknown knob 'colour'"),
                       ("extent=huge", "extent must be one of"), ("sh=5", "sh must be 0..3"),
                       ("half=maybe", "expected on or off"), ("min_alpha=x", "expected a number"),
                       ("alpha_max=2", "alpha_max must be in (0, 1]")]:
        with pytest.raises(SplatglError, match=None) as err:
            parse_knob(bad)
        assert words in str(err.value) and bad in str(err.value)


def test_quad_variants_map_onto_knobs():
    assert quad_emulation(RenderSettings()) == Emulation(extent="opacity")
    assert quad_emulation(RenderSettings(sort_key=SortKey.BUCKET16, extent=QuadExtent.FAST,
                                         gpu_storage=GpuStorage.COMPACT)) == Emulation(
        sort="bucket16", extent="fixed-quad", half=True)
    assert quad_emulation(RenderSettings(extent=QuadExtent.SQUARE)).extent == "square"


def test_gpu_renderers_refuse_an_emulation():
    from splatgl.renderers.registry import check_fidelity
    settings = RenderSettings(emulation=Emulation(extent="fixed"))
    with pytest.raises(SplatglError, match="applies to the NumPy reference only"):
        check_fidelity(settings, "quad")
    check_fidelity(settings, "quad", "reference")
