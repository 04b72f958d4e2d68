"""Depth layers: quad (same pass, second target), tile and reference agree; EXR Z; preview.

Tolerances: the accumulated depth D = sum z alpha T is z times colour-like weights, so the quad
path's differences from the reference scale with z: |D_quad - D_ref| <= z_max * 0.04 (the
alpha bound of test_compare.py).  The tile renderer follows the reference to float32 rounding.
"""

from __future__ import annotations

import numpy as np
import OpenImageIO as oiio
import pytest

from splatgl.cameras.camera import Camera
from splatgl.cli import main
from splatgl.constants import SH_C0
from splatgl.imagefiles.images import read_image
from splatgl.api import default_camera, render_reference_layers
from splatgl.scene.splats import Scene
from splatgl.scene.settings import RendererKind, RenderSettings


def _scene(n=800, seed=3):
    rng = np.random.default_rng(seed)
    return Scene(rng.normal(size=(n, 3)), rng.normal(size=(n, 4)), rng.normal(-3.0, 0.4, (n, 3)),
                 rng.normal(1.0, 1.5, n), rng.normal(0, 0.3, (n, 4, 3)))


def test_single_splat_expected_depth_is_its_z(gl_renderer):
    sh = np.zeros((1, 1, 3))
    sh[0, 0] = (0.7 - 0.5) / SH_C0
    scene = Scene.from_activated(np.array([[0.1, 0.0, 3.5]]), np.array([[1.0, 0, 0, 0]]),
                                 np.array([[0.3, 0.2, 0.25]]), np.array([0.8]), sh)
    cam = Camera(48, 40, 50.0, 50.0, 24.0, 20.0)
    out = gl_renderer.render_layers(scene, cam)
    drawn = out.alpha >= 1e-3
    assert drawn.sum() > 50
    np.testing.assert_allclose(out.expected_depth()[drawn], 3.5, rtol=1e-6)
    assert np.all(out.expected_depth()[~drawn] == 0.0)
    np.testing.assert_allclose(out.depth, 3.5 * out.alpha, rtol=1e-6, atol=1e-7)


@pytest.mark.parametrize("ortho", [False, True])
def test_quad_tile_reference_depth_agree(gl_renderer, ortho):
    scene = _scene()
    cam = default_camera(scene, 96, 72)
    if ortho:
        cam = Camera.orthographic(96, 72, 12.0, cam.world_to_camera)
    ref = render_reference_layers(scene, cam, RenderSettings())
    zmax = float((ref.expected_depth() * (ref.alpha > 1e-3)).max())
    assert zmax > 0
    quad = gl_renderer.render_layers(scene, cam, RenderSettings(), RendererKind.QUAD)
    tile = gl_renderer.render_layers(scene, cam, RenderSettings(), RendererKind.TILE)
    np.testing.assert_allclose(quad.depth, ref.depth, atol=0.04 * zmax)
    np.testing.assert_allclose(tile.depth, ref.depth, atol=1e-5 * zmax)
    # Colour from the depth-enabled pass is the colour of the plain pass.
    np.testing.assert_array_equal(quad.rgba, gl_renderer.render(scene, cam))


def test_exr_z_channel_and_depth_png(tmp_path):
    exr, png = tmp_path / "v.exr", tmp_path / "d.png"
    assert main(["render", "-o", str(exr), "--depth-png", str(png), "--width", "160", "--height", "90"]) == 0
    spec = oiio.ImageInput.open(str(exr)).spec()
    assert tuple(spec.channelnames) == ("R", "G", "B", "A", "Z")
    px = read_image(exr)
    z, a = px[..., 4], px[..., 3]
    assert np.all(z[a < 1e-3] == 0.0) and np.all(z[a > 0.5] > 0)
    prev = read_image(png)
    assert prev.shape[0] > 90 and prev.shape[1] == 160  # the scale bar sits below the image
