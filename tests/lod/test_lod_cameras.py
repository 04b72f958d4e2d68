"""Level of detail through every camera model and renderer (issue 39 item 1).

A cut at the leaves must draw what the plain scene draws.  The scene is a shell of splats
5-85 degrees off the camera axis, so a lens camera sees splats far outside the pinhole
frustum of its own intrinsics: the level-of-detail path once sent lens cameras to the pinhole
cull (a 180-degree fisheye lost everything beyond about 60-70 degrees, a panorama about a
third of its pixels), with no message.
"""

from __future__ import annotations

import numpy as np
import pytest

from helpers import draw, scene_with_colors
from splatgl.cameras.camera import Camera
from splatgl.cameras.opencv import OpenCV
from splatgl.cameras.view import View
from splatgl.lod.build import build_hierarchy
from splatgl.lod.cut import CutData, select_cut_weights
from splatgl.lod.selection import LodSettings, blended_scene
from splatgl.lod.source import lod_renderer
from splatgl.scene.settings import RenderSettings
from splatgl.renderers.registry import refusal
from splatgl.renderers.stereo import eye_cameras

W, H = 48, 32
#: A threshold no node of this scene projects below: the cut is the leaves in view.
LEAVES_PX = 1e-5


def _shell(n: int = 2000, seed: int = 7):
    """``n`` splats 2.5-3.5 units from the origin, 5-85 degrees off the +z axis."""
    rng = np.random.default_rng(seed)
    theta = np.radians(rng.uniform(5.0, 85.0, n))
    phi = rng.uniform(0.0, 2.0 * np.pi, n)
    r = rng.uniform(2.5, 3.5, n)
    means = np.stack([r * np.sin(theta) * np.cos(phi), r * np.sin(theta) * np.sin(phi),
                      r * np.cos(theta)], 1)
    return scene_with_colors(means, rng.normal(size=(n, 4)), np.exp(rng.normal(-3.0, 0.3, (n, 3))),
                             rng.uniform(0.3, 0.9, n), rng.uniform(0, 1, (n, 3)))


def _cameras(w: int, h: int) -> dict[str, Camera]:
    ods = eye_cameras(Camera.equirectangular(2 * h, h), 0.3)
    return {
        "perspective": Camera.from_fov(w, h, 100.0),
        "orthographic": Camera.orthographic(w, h, w / 7.0),
        "fisheye": Camera.fisheye(w, h, 180.0),
        "opencv": Camera(w, h, 0.3 * w, 0.3 * w, w / 2, h / 2, np.eye(4), OpenCV(k1=-0.3, k2=0.05)),
        "equirectangular": Camera.equirectangular(2 * h, h),
        "stereo-left": ods[0],
        "stereo-right": ods[1],
    }


MODELS = list(_cameras(W, H))


@pytest.fixture(scope="module")
def shell():
    scene = _shell()
    return scene, build_hierarchy(scene, branching=4)


def _leaf_cut(tree, camera: Camera):
    """The scene of the cut at the leaves (:func:`blended_scene`), as any renderer draws it."""
    rows, weights = select_cut_weights(CutData.from_tree(tree), camera, LEAVES_PX)
    return blended_scene(tree, rows, weights)


def _same(got: np.ndarray, want: np.ndarray) -> None:
    lit_got, lit_want = (int((a[..., 3] > 1 / 255).sum()) for a in (got, want))
    assert lit_want > 0.05 * want.shape[0] * want.shape[1]
    assert lit_got == lit_want, f"{lit_got} pixels lit of the plain scene's {lit_want}"
    # the leaves are stored in float32 relative to the node scene's anchor, not the plain
    # scene's: rounding only (measured: max 0.006, mean 4e-5 at most)
    err = np.abs(got - want)
    assert err.max() < 0.02 and err.mean() < 1e-4


@pytest.mark.parametrize("model", MODELS)
@pytest.mark.parametrize("cut", [LodSettings(threshold_px=LEAVES_PX, band=1.0),
                                 LodSettings(threshold_px=LEAVES_PX, budget=10**6, band=1.0)],
                         ids=["threshold", "budget"])
def test_quad_cut_at_the_leaves_draws_the_plain_scene(ctx, shell, model, cut):
    """The quad path's level-of-detail source (the cut's frustum test, the cut's cull and sort,
    and the switch to the leaves) against the plain scene's order stage."""
    from splatgl.renderers.quad import QuadRenderer

    scene, tree = shell
    camera = _cameras(W, H)[model]
    settings = RenderSettings()
    plain = QuadRenderer(ctx, scene, settings)
    lod = lod_renderer(ctx, tree, settings, cut)
    try:
        want = draw(plain, camera).rgba
        for _ in range(2):     # the threshold's cut switches to the leaves on its first view
            _same(draw(lod, camera).rgba, want)
    finally:
        plain.release()
        lod.release()


@pytest.mark.parametrize("model", [m for m in MODELS
                                   if refusal("tile", model=_cameras(W, H)[m].model) is None])
def test_tile_cut_at_the_leaves_draws_the_plain_scene(ctx, shell, model):
    from splatgl.renderers.tile import TileRenderer

    scene, tree = shell
    camera = _cameras(W, H)[model]
    settings = RenderSettings()
    images = []
    for drawn in (scene, _leaf_cut(tree, camera)):
        renderer = TileRenderer(ctx, drawn, settings)
        try:
            images.append(renderer.render(View.of(camera, settings, drawn)).rgba)
        finally:
            renderer.release()
    _same(images[1], images[0])


@pytest.mark.parametrize("model", MODELS)
def test_cpu_cut_at_the_leaves_draws_the_plain_scene(shell, model):
    from splatgl.renderers import cpu
    from splatgl.renderers.registry import installed

    if not installed("cpu"):
        pytest.skip("the CPU renderer needs numba")
    scene, tree = shell
    camera = _cameras(W, H)[model]
    settings = RenderSettings()
    images = [cpu.CpuRenderer(drawn, settings).render(View.of(camera, settings, drawn)).rgba
              for drawn in (scene, _leaf_cut(tree, camera))]
    _same(images[1], images[0])


@pytest.mark.parametrize("model", MODELS)
def test_reference_cut_at_the_leaves_draws_the_plain_scene(shell, model):
    from splatgl.reference import render_reference

    scene, tree = shell
    camera = _cameras(24, 16)[model]
    settings = RenderSettings()
    images = [render_reference(drawn, camera, settings, np.float32).rgba
              for drawn in (scene, _leaf_cut(tree, camera))]
    _same(images[1], images[0])


@pytest.mark.parametrize("model", MODELS)
def test_compiled_cut_and_cull_are_numpys(ctx, shell, compiled_kernels, model):
    """The compiled cut (numba) tests each model's frustum as the NumPy cut does (the same rows
    and weights), and the cut's compiled cull (a lens camera's lens_pass over the cut's rows)
    gives NumPy's order, at a fine and a coarse threshold."""
    from splatgl.order import kernels as cull_kernel

    if not cull_kernel.installed():
        pytest.skip("numba not installed (pip install '.[fast]')")
    kern = cull_kernel.kernel(wait=True)
    scene, tree = shell
    camera = _cameras(W, H)[model]
    data = CutData.from_tree(tree)
    for threshold, band in ((LEAVES_PX, 1.0), (0.5, 1.0), (2.0, 2.0)):
        want = select_cut_weights(data, camera, threshold, band)
        got = select_cut_weights(data, camera, threshold, band, kern=kern)
        for a, b in zip(got, want):
            assert (a is None) == (b is None)
            if a is not None:
                np.testing.assert_array_equal(a, b)
    settings = RenderSettings()
    orders = []
    for policy in ("off", "wait"):
        cull_kernel.set_policy(policy)
        lod = lod_renderer(ctx, tree, settings, LodSettings(threshold_px=0.5, budget=10**6))
        try:
            orders.append([lod.order(View.of(camera, settings, tree.nodes)).copy() for _ in range(2)])
        finally:
            cull_kernel.set_policy("auto")
            lod.release()
    for a, b in zip(*orders):
        np.testing.assert_array_equal(a, b)
