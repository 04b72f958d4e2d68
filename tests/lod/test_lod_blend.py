"""Level of detail across a transition band: the opacity weights of the blended cut (partition
of unity along every path, continuity as the camera moves), the pre-pass that applies them
against its NumPy twin, and the options that ask for them."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest
from hypothesis import given, settings as hsettings, strategies as st

from splatgl.cameras.camera import Camera
from splatgl.cameras.poses import look_at
from splatgl.errors import SplatglError
from splatgl.formats import load_scene
from splatgl.lod.build import build_hierarchy
from splatgl.lod.cut import CutData, expansion, select_cut, select_cut_weights
from splatgl.lod.selection import LodSettings, blended_scene, leaves_covered
from splatgl.lod.source import lod_renderer
from helpers import draw, view_of
from splatgl.measure.evaluation.metrics import image_errors
from splatgl.renderers.quad import QuadRenderer
from splatgl.api import default_camera
from splatgl.scene.splats import Scene
from splatgl.scene.settings import Preprocess, RenderSettings

from helpers import shared_file

N = 3000


@pytest.fixture(scope="module")
def tree():
    rng = np.random.default_rng(7)
    scene = Scene(rng.uniform(-1, 1, (N, 3)), rng.normal(size=(N, 4)), rng.normal(-3.5, 0.4, (N, 3)),
                  rng.normal(1, 1, N), rng.normal(0, 0.3, (N, 4, 3)))
    return build_hierarchy(scene, branching=4)


def _camera(distance: float, fov: float = 100.0) -> Camera:
    """Looking at the [-1, 1]^3 scene from ``distance``; at fov 100 and distance >= 3 it is all
    in view (every subtree passes the frustum test)."""
    return Camera.from_fov(320, 180, fov, look_at(np.array([0.3, 0.2, -distance]), np.zeros(3)))


def _dense_weights(tree, rows, weights) -> np.ndarray:
    full = np.zeros(tree.nodes.count, np.float64)
    full[rows] = 1.0 if weights is None else weights
    return full


def _weight_per_leaf(tree, rows, weights) -> np.ndarray:
    """Sum of the drawn weights over each leaf's ancestors-or-self (difference array over the
    leaf ranges of the nodes)."""
    acc = np.zeros(N + 1)
    w = np.ones(rows.size) if weights is None else weights.astype(np.float64)
    level = np.searchsorted(tree.offsets, rows, side="right") - 1
    span = tree.branching ** level
    first = (rows - tree.offsets[level]) * span
    np.add.at(acc, first, w)
    np.add.at(acc, np.minimum(first + span, N), -w)
    return np.cumsum(acc)[:N]


def test_expansion_is_a_clamped_ramp_across_the_band():
    size = np.array([0.5, 2.0, 3.0, 4.0, 5.0, np.inf], np.float32)
    np.testing.assert_allclose(expansion(size, 2.0, 2.0), [0, 0, 0.5, 1, 1, 1])
    np.testing.assert_array_equal(expansion(size, 2.0, 1.0), [0, 0, 1, 1, 1, 1])
    np.testing.assert_array_equal(expansion(size, np.inf, 2.0), np.zeros(6))


@hsettings(max_examples=25)
@given(threshold=st.floats(0.3, 12.0), band=st.floats(1.05, 4.0), distance=st.floats(3.0, 30.0))
def test_weights_sum_to_one_along_every_path(tree, threshold, band, distance):
    """Every leaf is in view, so every root-to-leaf path carries total weight 1 (the weights
    telescope), and the drawn nodes are the plain cut's plus those inside the band."""
    data = CutData.from_tree(tree)
    cam = _camera(distance)
    rows, w = select_cut_weights(data, cam, threshold, band)
    assert (np.diff(rows) > 0).all()
    if w is not None:
        assert w.dtype == np.float32 and (w > 0).all() and (w <= 1).all()
    np.testing.assert_allclose(_weight_per_leaf(tree, rows, w), 1.0, atol=1e-5)
    assert set(select_cut(data, cam, threshold).tolist()) <= set(rows.tolist())
    assert leaves_covered(tree, rows, w) == pytest.approx(N, rel=1e-4)  # all leaves in view


@hsettings(max_examples=30)
@given(threshold=st.floats(0.3, 12.0), band=st.floats(1.0, 3.0), distance=st.floats(3.0, 30.0),
       leaves_at=st.floats(0.3, 1.0))
def test_early_exit_before_the_leaves_matches_the_whole_cut(tree, threshold, band, distance,
                                                            leaves_at):
    """With every leaf in view, ``leaves_at`` stops before the leaf level exactly when the
    whole cut draws at least that many nodes per leaf it stands for; otherwise the cut is the
    same as without it."""
    data = CutData.from_tree(tree)
    cam = _camera(distance)
    rows, w = select_cut_weights(data, cam, threshold, band)
    ratio = rows.size / leaves_covered(tree, rows, w)
    has_leaves = bool((rows < tree.offsets[1]).any())
    got_rows, got_w = select_cut_weights(data, cam, threshold, band, leaves_at=leaves_at)
    if got_rows is None:
        assert got_w is None and has_leaves and ratio >= leaves_at * (1 - 1e-6)
    else:
        np.testing.assert_array_equal(got_rows, rows)
        assert (got_w is None) == (w is None) and (w is None or np.array_equal(got_w, w))
        assert not has_leaves or ratio < leaves_at * (1 + 1e-6)


def test_no_band_is_the_plain_cut(tree):
    data = CutData.from_tree(tree)
    rows, w = select_cut_weights(data, _camera(6.0), 2.0, 1.0)
    assert w is None
    np.testing.assert_array_equal(_weight_per_leaf(tree, rows, None), 1.0)  # each leaf once


@pytest.mark.slow
@hsettings(max_examples=6)
@given(threshold=st.floats(0.5, 6.0), band=st.floats(1.5, 3.0), start=st.floats(4.0, 12.0))
def test_weights_change_continuously_along_a_fly_in(tree, threshold, band, start):
    """Steps of 0.2% in camera distance change a projected size s = f r / (d - r) by at most
    0.2% d / (d - 1.8) < 0.5% (d >= 3, every node within 1.8 of the centre), so a node's
    expansion e (slope 1 / (T (band - 1)) over sizes <= band T) moves by at most
    0.5% * band / (band - 1) <= 0.015, and a weight A (1 - e), a
    product over the (at most two, measured) band nodes of a path, by at most 0.03.  The same
    path without a band jumps by a whole weight (1.0): the check has power."""
    data = CutData.from_tree(tree)
    prev_blend = prev_hard = None
    worst_blend = worst_hard = 0.0
    d = start
    for _ in range(120):
        cam = _camera(d)
        blend = _dense_weights(tree, *select_cut_weights(data, cam, threshold, band))
        hard = _dense_weights(tree, *select_cut_weights(data, cam, threshold, 1.0))
        if prev_blend is not None:
            worst_blend = max(worst_blend, float(np.abs(blend - prev_blend).max()))
            worst_hard = max(worst_hard, float(np.abs(hard - prev_hard).max()))
        prev_blend, prev_hard, d = blend, hard, d * 0.998
    assert worst_blend <= 0.03
    if worst_hard > 0:  # the plain cut changed along this stretch: by whole nodes
        assert worst_hard == 1.0


@pytest.fixture(scope="module")
def biker(shared_scenes):
    scene = load_scene(shared_file(shared_scenes, "compressed_ply/biker.compressed.ply"))
    return scene, build_hierarchy(scene)


@pytest.mark.slow
def test_prepass_weights_match_the_numpy_twin(ctx, biker):
    """The pre-pass's weighted opacities (OPACITY_WEIGHT) draw what the quad path draws for the
    cut as a plain scene with those opacities (blended_scene): measured 0.00016 max error (the
    two scenes' anchors differ: float32 rounding of the centres).  Against full detail the
    band mixes in coarser parents: measured 38.4 dB with 84k nodes, against 40.5 dB for the
    plain cut at 1 px with 69k."""
    scene, tree = biker
    camera = default_camera(scene, 200, 112, distance_scale=2.5)
    lod = lod_renderer(ctx, tree, RenderSettings(), LodSettings(threshold_px=1.0, band=2.0))
    plain = lod_renderer(ctx, tree, RenderSettings(), LodSettings(threshold_px=1.0, band=1.0))
    full = QuadRenderer(ctx, scene, RenderSettings())
    try:
        got = draw(lod, camera).rgba
        assert lod.rows.slot_weights is not None and (lod.rows.slot_weights < 1).any()
        rows, weights = select_cut_weights(lod.rows.cut_data, camera, 1.0, 2.0)
        twin = QuadRenderer(ctx, blended_scene(tree, rows, weights), RenderSettings())
        want = draw(twin, camera).rgba
        twin.release()
        assert float(np.abs(got - want).max()) <= 2e-3
        hard = draw(plain, camera).rgba
        assert float(np.abs(got - hard).max()) > 1e-2  # the weights do change the image
        assert lod.rows.last_cut_nodes > plain.rows.last_cut_nodes
        reference = draw(full, camera).rgba
        psnr_blend = image_errors(got, reference).psnr
        psnr_hard = image_errors(hard, reference).psnr
        assert psnr_blend >= 37.5 and psnr_hard - 3.0 <= psnr_blend < psnr_hard
    finally:
        lod.release()
        plain.release()
        full.release()


def test_band_needs_the_prepass_and_a_ratio(ctx, biker):
    _, tree = biker
    with pytest.raises(SplatglError, match=r"^--lod-blend 2 weights opacities in the compute "
                                           r"pre-pass: use --preprocess compute \(the default\), "
                                           r"or --lod-blend 1$"):
        lod_renderer(ctx, tree, RenderSettings(preprocess=Preprocess.VERTEX), LodSettings(band=2.0))
    with pytest.raises(SplatglError, match=r"^--lod-blend must be a ratio of at least 1 \(1: no "
                                           r"blending\), got 0.5$"):
        LodSettings(band=0.5)


@pytest.mark.slow
def test_cli_lod_blend(tmp_path, shared_scenes):
    src = shared_file(shared_scenes, "ply/donut_sh0.ply")
    lod = tmp_path / "donut.lod.ply"
    run = lambda *a: subprocess.run([sys.executable, "-m", "splatgl", *map(str, a)],
                                    capture_output=True, text=True)
    assert run("lod", src, "-o", lod).returncode == 0
    for band in ("1", "3"):
        proc = run("render", lod, "--lod-threshold", "2", "--lod-blend", band, "--width", "96",
                   "--height", "64", "--distance", "3", "-o", tmp_path / f"b{band}.png")
        assert proc.returncode == 0, proc.stderr
    proc = run("render", lod, "--lod-blend", "0.5", "-o", tmp_path / "x.png")
    assert proc.returncode == 2
    assert proc.stderr.strip() == ("splatgl: error: --lod-blend must be a ratio of at least 1 "
                                   "(1: no blending), got 0.5")


def test_cut_override_draws_an_earlier_views_cut(ctx, biker):
    """What the benchmark's cut-change measure rests on: the same camera through its own cut
    (given back as ``cut_override``) draws the same image bit for bit; a nearer camera through
    the farther view's cut draws fewer nodes than its own cut."""
    scene, tree = biker
    far = default_camera(scene, 96, 64, distance_scale=4.0)
    near = default_camera(scene, 96, 64, distance_scale=3.0)
    lod = lod_renderer(ctx, tree, RenderSettings(), LodSettings(threshold_px=1.0, band=2.0))
    try:
        img = draw(lod, far).rgba
        cut = lod.rows.last_cut
        lod.rows.cut_override = cut
        np.testing.assert_array_equal(draw(lod, far).rgba, img)
        frozen_nodes = lod.rows.last_cut_nodes
        lod.rows.cut_override = None
        draw(lod, near).rgba
        assert lod.rows.last_cut_nodes > frozen_nodes and lod.rows.last_cut is not cut
    finally:
        lod.release()


@pytest.mark.parametrize("sort", ["exact", "bucket16"])
def test_cut_cull_compiled_or_numpy_same_order_and_weights(ctx, biker, sort):
    """The cut's cull runs compiled (numba, in place over the cut's rows) or in NumPy (over
    the gathered rows): the same sorted rows and the same per-slot weights either way, for the
    exact sort and for a sort that takes depths (keys_pairs)."""
    from splatgl.order import kernels as cull_kernel
    from splatgl.scene.settings import SortKey

    if not cull_kernel.installed():
        pytest.skip("numba not installed (pip install '.[fast]')")
    assert cull_kernel.kernel(wait=True) is not None, "numba is installed but the kernels failed to load"
    scene, tree = biker
    settings = RenderSettings(sort_key=SortKey(sort))
    got = {}
    for policy in ("off", "wait"):
        cull_kernel.set_policy(policy)
        lod = lod_renderer(ctx, tree, settings, LodSettings(threshold_px=1.0, band=2.0))
        try:
            for scale in (2.5, 3.5):  # two views: the second is where "auto" would switch
                camera = default_camera(scene, 200, 112, distance_scale=scale)
                got[policy, scale] = (lod.order(view_of(camera, tree.nodes, settings)).copy(), lod.rows.slot_weights)
                assert not lod.rows.last_drew_leaves and lod.rows.slot_weights is not None
        finally:
            cull_kernel.set_policy("auto")
            lod.release()
    for scale in (2.5, 3.5):
        for a, b in zip(got["off", scale], got["wait", scale]):
            np.testing.assert_array_equal(a, b)


@hsettings(max_examples=40)
@given(threshold=st.floats(0.3, 12.0), band=st.sampled_from([1.0, 1.5, 2.0, 3.0]),
       distance=st.floats(0.5, 30.0), fov=st.floats(30.0, 110.0),
       leaves_at=st.sampled_from([None, 0.5, 0.75, 1.0]), ortho=st.booleans())
def test_compiled_cut_selects_what_numpy_selects(tree, compiled_kernels, threshold, band,
                                                 distance, fov, leaves_at, ortho):
    """The compiled cut (numba; over the candidates only) gives the NumPy cut's rows and the
    same weight bits, or the same decision to draw the leaves, for cameras inside and outside
    the scene (frustum tests), perspective and orthographic, any band, and the root's cut."""
    from splatgl.order import kernels as cull_kernel

    if not cull_kernel.installed():
        pytest.skip("numba not installed (pip install '.[fast]')")
    kern = cull_kernel.kernel(wait=True)
    assert kern is not None, "numba is installed but the kernels failed to load"
    data = CutData.from_tree(tree)
    pose = look_at(np.array([0.3, 0.2, -distance]), np.array([0.4, -0.1, 0.0]))
    cam = (Camera.orthographic(320, 180, 120.0 / (1 + distance), pose) if ortho
           else Camera.from_fov(320, 180, fov, pose))
    for t in (threshold, np.inf):
        want = select_cut_weights(data, cam, t, band, leaves_at)
        got = select_cut_weights(data, cam, t, band, leaves_at, kern=kern)
        for a, b in zip(got, want):
            assert (a is None) == (b is None)
            if a is not None:
                assert a.dtype == b.dtype
                np.testing.assert_array_equal(a, b)
