"""Lean memory (the refusal of a scene too big for the memory left is in
tests/formats/test_loader_messages.py): the GPU upload and the cull's per-scene data are built chunk by chunk with the same values."""

from __future__ import annotations


import numpy as np
import pytest

from splatgl.order.cull import CullData
from splatgl.gl import scene_buffers
from splatgl.scene.splats import Scene
from splatgl.scene.settings import GpuStorage
from splatgl.gl.storage import COMPACT_WORDS, encode_compact, gpu_bytes_per_splat



def _scene(n: int, degree: int) -> Scene:
    rng = np.random.default_rng(5)
    quats = rng.normal(size=(n, 4))
    quats[3] = 0.0  # degenerate: opacity 0, identity rotation
    return Scene(rng.normal(size=(n, 3)) + 100.0, quats, rng.normal(-3, 1, (n, 3)),
                 rng.normal(size=n), rng.normal(0, 0.3, (n, (degree + 1) ** 2, 3)))


@pytest.mark.parametrize("storage", list(GpuStorage))
def test_chunked_upload_equals_whole_scene_layout(ctx, monkeypatch, storage):
    monkeypatch.setattr(scene_buffers, "UPLOAD_ROWS", 1000)
    scene = _scene(2501, 2)  # 3 chunks, the last partial; odd count x 24 halves
    bufs = scene_buffers.SceneBuffers(ctx, scene, storage)
    try:
        n = scene.count
        if storage is GpuStorage.COMPACT:
            words = encode_compact(scene.relative_means, scene.opacities, scene.rotations,
                                   scene.scales, scene.sh[:, 0], bufs.scale_exponent)
            got = np.frombuffer(bufs.packed.read(), np.uint32).reshape(n, COMPACT_WORDS)
            np.testing.assert_array_equal(got, words)
            assert bufs.a is bufs.q is bufs.s is bufs.dc is None
        else:
            got = {k: np.frombuffer(getattr(bufs, k).read(), np.float32).reshape(n, 4)
                   for k in ("a", "q", "s", "dc")}
            np.testing.assert_array_equal(got["a"][:, :3], scene.relative_means)
            np.testing.assert_array_equal(got["a"][:, 3], scene.opacities)
            np.testing.assert_array_equal(got["q"], scene.rotations)
            np.testing.assert_array_equal(got["s"][:, :3], scene.scales)
            np.testing.assert_array_equal(got["dc"][:, :3], scene.sh[:, 0])
        dtype = np.float32 if storage is GpuStorage.FLOAT32 else np.float16
        rest = np.frombuffer(bufs.sh.read(), dtype)[:n * 24]
        np.testing.assert_array_equal(rest, scene.sh[:, 1:].astype(dtype).ravel())
        assert bufs.nbytes >= n * gpu_bytes_per_splat(storage, 2)
        assert bufs.nbytes <= n * gpu_bytes_per_splat(storage, 2) + 4
    finally:
        bufs.release()


def test_cull_data_from_scene_in_blocks_equals_whole_arrays():
    scene = _scene(2501, 0)
    data = CullData.from_scene(scene, block=700)
    whole = CullData(scene.relative_means, scene.scales.max(axis=1), scene.opacities)
    for name in ("xyz", "radius", "max_scale", "opacities", "alive", "faint"):
        np.testing.assert_array_equal(getattr(data, name), getattr(whole, name), name)
