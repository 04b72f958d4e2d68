"""The peak-alpha bound's float32 decision (:func:`splatgl.order.cull.peak_keeps`, twin of
shaders/order_cull.comp's ``peak_keeps``) on splats placed right at the 1/255 cut: it is the
float64 bound's decision away from float32 rounding, and the compiled cull (numba), whose
float64 bound hands the rows near the cut back to it, keeps the same splats."""

from __future__ import annotations

import numpy as np
import pytest

from splatgl.cameras.camera import Camera
from splatgl.order import chunks as cull_chunks, kernels as cull_kernel
from splatgl.order.chunks import ChunkedCull
from splatgl.order.cull import ALPHA_MIN, CullData, cull_visible, peak_alpha_bound, peak_keeps


def _at_cut(cam: Camera, n: int, antialias: bool = False, spread: float = 3e-3, seed: int = 1):
    """(points (n, 3) float32 in camera space, max_scale, opacity, float64 bound / (1/255)):
    splats whose brightest pixel centre is within ``spread`` (relative) of 1/255."""
    rng = np.random.default_rng(seed)
    m = 6 * n
    uv = rng.uniform([-2.0, -2.0], [cam.width + 2.0, cam.height + 2.0], (m, 2))
    z = rng.uniform(1.0, 4.0, m)
    if cam.is_orthographic:
        p = np.stack([(uv[:, 0] - cam.cx) / cam.fx, (uv[:, 1] - cam.cy) / cam.fy, z], 1)
    else:
        p = np.stack([(uv[:, 0] - cam.cx) * z / cam.fx, (uv[:, 1] - cam.cy) * z / cam.fy, z], 1)
    p = p.astype(np.float32)
    ms = np.exp(rng.uniform(np.log(1e-5), np.log(3e-3), m)).astype(np.float32)
    fall = peak_alpha_bound(p, ms, np.ones(m), cam, antialias)
    opac = ((1 + rng.uniform(-spread, spread, m)) / (255 * fall)).astype(np.float32)
    pick = np.flatnonzero(opac < 0.95)[:n]
    assert pick.size == n
    p, ms, opac = p[pick], ms[pick], opac[pick]
    ratio = peak_alpha_bound(p, ms, opac, cam, antialias) / ALPHA_MIN
    return p, ms, opac, ratio


CAMERAS = {"pinhole": Camera.from_fov(320, 200, 60.0), "orthographic": Camera.orthographic(320, 200, 80.0),
           "wide": Camera(2000, 1200, 900.0, 900.0, 1000.0, 600.0, np.eye(4))}


@pytest.mark.parametrize("antialias", [False, True])
@pytest.mark.parametrize("name", list(CAMERAS))
def test_float32_decision_is_the_float64_bound_away_from_rounding(name, antialias):
    cam = CAMERAS[name]
    p, ms, opac, ratio = _at_cut(cam, 4000, antialias)
    keep = peak_keeps(p, np.arange(p.shape[0]), CullData(p, ms, opac), cam, antialias, 1.0)
    sure = np.abs(ratio - 1) > 1e-3
    np.testing.assert_array_equal(keep[sure], ratio[sure] >= 1)
    assert keep.any() and not keep.all() and sure.sum() > 0.5 * p.shape[0]


def test_cull_visible_takes_the_float32_decision():
    """The pinhole cull's kept set at the cut is the float32 decision's (not the float64's)."""
    cam = CAMERAS["pinhole"]
    p, ms, opac, _ = _at_cut(cam, 4000, spread=1e-5)
    data = CullData(p, ms, opac)
    idx, _ = cull_visible(data, cam, 0.05)
    keep = peak_keeps(p, np.arange(p.shape[0]), data, cam, False, 1.0)
    np.testing.assert_array_equal(idx, np.flatnonzero(keep))   # all faint or outside the image


@pytest.mark.parametrize("split", [False, True])
def test_compiled_cull_keeps_the_float32_decision_at_the_cut(split, monkeypatch):
    if not cull_kernel.installed():
        pytest.skip("numba not installed (pip install '.[fast]')")
    assert cull_kernel.kernel(wait=True) is not None
    monkeypatch.setattr(cull_chunks, "SPLIT_ROWS", 1 if split else 10 ** 9)
    monkeypatch.setattr(cull_chunks, "WHOLE_SHARE", 0.0)    # every row through the compiled pass
    cam = CAMERAS["wide"]
    p, ms, opac, _ = _at_cut(cam, 3000, spread=3e-3)
    data = CullData(p, ms, opac)
    compiled = ChunkedCull(data, chunk=32, group=8)
    compiled.compiled = True
    got = np.sort(compiled.visible_keys(cam, 0.05))
    assert compiled.last_path == "compiled"
    plain = ChunkedCull(data, chunk=32, group=8)
    plain.compiled = False
    want = np.sort(plain.visible_keys(cam, 0.05))
    assert 0 < want.size < p.shape[0]
    np.testing.assert_array_equal(got, want)
