"""The blocked float32 cull (:func:`splatgl.order.cull.cull_visible`) keeps exactly what the float64
cull (:func:`splatgl.order.cull.cull`) keeps, with the same depths, on cameras that cut the scene."""

from __future__ import annotations

import numpy as np
import pytest

from splatgl.cameras.camera import Camera
from splatgl.cameras.poses import look_at
from splatgl.order.cull import CULL_BLOCK, CullData, cull, cull_visible
from splatgl.splatmath.project import to_camera


def _scene_arrays(n: int, seed: int):
    rng = np.random.default_rng(seed)
    points = rng.uniform(-3, 3, (n, 3)).astype(np.float32)
    max_scale = np.exp(rng.normal(-3.5, 1.2, n)).astype(np.float32)
    # opacities spanning the faint range (below 0.009 the peak bound can cull inside the image)
    opac = np.concatenate([rng.uniform(0, 0.02, n // 4), rng.uniform(0, 1, n - n // 4)])
    return points, max_scale, rng.permutation(opac).astype(np.float32)


def _cameras():
    eye_far = look_at(np.array([0.3, -0.5, -9.0]), np.zeros(3))
    eye_inside = look_at(np.array([0.2, 0.1, -0.5]), np.array([1.0, 0.5, 2.0]))  # many behind
    edge = look_at(np.array([-6.0, 0.0, -4.0]), np.array([2.0, 0.0, 3.0]))  # scene at the edge
    scaled = eye_far.copy()
    scaled[:3, :3] *= 2.5  # a scene transform's uniform scale folded in
    off_centre = Camera(320, 200, 260.0, 240.0, 40.0, 170.0, edge)
    return [Camera.from_fov(640, 360, 50.0, eye_far), Camera.from_fov(300, 400, 80.0, eye_inside),
            off_centre, Camera.from_fov(640, 360, 30.0, scaled),
            Camera.orthographic(200, 150, 40.0, eye_far)]


@pytest.mark.parametrize("antialias", [False, True])
@pytest.mark.parametrize("cam_index", range(5))
def test_blocked_cull_equals_float64_cull(cam_index, antialias):
    n = 2 * CULL_BLOCK + 1234  # a partial last block
    points, max_scale, opac = _scene_arrays(n, 11 + cam_index)
    camera = _cameras()[cam_index]
    near = 0.05
    want = np.flatnonzero(cull(to_camera(points, camera), max_scale * camera.scale, opac, camera,
                               near, antialias))
    idx, z = cull_visible(CullData(points, max_scale, opac), camera, near, antialias,
                          camera.scale)
    assert 0 < want.size < n  # the camera really cuts the scene
    assert idx.dtype == np.uint32 and z.dtype == np.float32
    np.testing.assert_array_equal(idx, want)
    np.testing.assert_array_equal(z, to_camera(points, camera)[want, 2])


def test_peak_bound_still_culls_faint_splats_inside_the_image():
    """A faint (o = 0.005) tiny splat between pixel centres is culled, a bright one kept."""
    camera = Camera.from_fov(64, 64, 60.0)
    f = camera.fx
    # centres at (32.0, 32.0) px: 0.5 px from the nearest pixel centres on both axes
    points = np.array([[0.0, 0.0, 1.0], [0.0, 0.0, 1.0]], np.float32)
    max_scale = np.full(2, 0.05 / f, np.float32)  # 0.05 px
    opac = np.array([0.005, 0.5], np.float32)
    idx, _ = cull_visible(CullData(points, max_scale, opac), camera, 0.01)
    np.testing.assert_array_equal(idx, [1])
