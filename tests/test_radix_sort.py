"""The device radix sort: its NumPy twin and the compute shaders give exactly the CPU sort's
order (depth, ties by index), bit for bit, and a quad frame sorted on the device is identical."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from helpers import draw, view_for
from splatgl.cameras.camera import Camera
from splatgl.cameras.poses import look_at
from splatgl.gl.radix_sort import (TILE_KEYS, RadixSorter, device_depth_sort, radix_passes,
                                   radix_sort_twin)
from splatgl.renderers.quad import QuadRenderer
from splatgl.model.scene import Scene
from splatgl.model.settings import RenderSettings, SortKey
from splatgl.order.sort import depth_sort


def _depths(n: int, seed: int, ties: bool) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    z = np.exp(rng.uniform(-3, 6, n)).astype(np.float32)  # exponents differ: all 8 passes
    if ties:
        z[rng.integers(0, n, n // 3)] = z[0]
    idx = np.sort(rng.choice(4 * n, n, replace=False)).astype(np.uint32)
    return z, idx


@given(st.lists(st.floats(2.0 ** -10, 8192.0, width=32), min_size=0, max_size=300))
@settings(max_examples=60)
def test_twin_equals_cpu_sort(values):
    z = np.array(values, np.float32)
    idx = np.arange(z.size, dtype=np.uint32) * 3
    _, got = radix_sort_twin(z.view(np.uint32), idx)
    np.testing.assert_array_equal(got, depth_sort(z, idx))


def test_passes_skip_shared_high_digits():
    keys = np.array([0x3F800000, 0x3F8000FF], np.uint32)  # differ in the low 8 bits only
    assert radix_passes(keys) == [0, 4]
    assert radix_passes(np.array([5, 5], np.uint32)) == []
    assert len(radix_passes(np.array([0, 0xFFFFFFFF], np.uint32))) == 8


@pytest.mark.parametrize("n", [1, 7, TILE_KEYS, TILE_KEYS + 1, 3 * TILE_KEYS + 123, 60_000])
@pytest.mark.parametrize("ties", [False, True])
def test_device_sort_equals_cpu_sort_bit_for_bit(ctx, n, ties):
    z, idx = _depths(n, n, ties)
    sorter = RadixSorter(ctx)
    try:
        keys, values = sorter.sort(z.view(np.uint32), idx)
        want = depth_sort(z, idx)
        np.testing.assert_array_equal(values, want)
        np.testing.assert_array_equal(keys, np.sort(z.view(np.uint32)))
        np.testing.assert_array_equal(device_depth_sort(sorter, z, idx), want)
    finally:
        sorter.release()


def test_quad_frame_with_device_sort_is_identical(ctx):
    rng = np.random.default_rng(3)
    n = 5000
    scene = Scene(rng.uniform(-1, 1, (n, 3)), rng.normal(size=(n, 4)), rng.normal(-3.5, 0.5, (n, 3)),
                  rng.normal(0, 2, n), rng.normal(0, 0.5, (n, 4, 3)))
    camera = Camera.from_fov(96, 64, 60.0, look_at(np.array([0.2, -0.3, -3.0]), np.zeros(3)))
    images, orders = [], []
    for key in (SortKey.EXACT, SortKey.GPU):
        r = QuadRenderer(ctx, scene, RenderSettings(sort_key=key))
        try:
            images.append(draw(r, camera).rgba)
            orders.append(r.order(view_for(r, camera)).copy())
        finally:
            r.release()
    np.testing.assert_array_equal(orders[1], orders[0])
    np.testing.assert_array_equal(images[1], images[0])
