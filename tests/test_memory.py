"""Lean memory: a scene too big for the memory left fails in one line before allocating; the
GPU upload and the cull's per-scene data are built chunk by chunk with the same values."""

from __future__ import annotations

import subprocess
import sys
import tracemalloc

import numpy as np
import pytest

from splatgl.cull import CullData
from splatgl.errors import SceneFormatError
from splatgl.formats import load_scene
from splatgl.gl import scene_buffers
from splatgl.memory import LIMIT_ENV, scene_bytes
from splatgl.scene import Scene

from conftest import shared_file


def test_scene_too_big_is_one_line_before_allocating(shared_scenes, monkeypatch):
    path = shared_file(shared_scenes, "ply/donut_sh0.ply")
    # 45,624 x (56 + 26) B = 3.7 MB, plus one read chunk of 45,624 rows x 56 B = 2.6 MB
    need = scene_bytes(45_624, 0) + 45_624 * 56
    monkeypatch.setenv(LIMIT_ENV, "3000000")
    tracemalloc.start()
    with pytest.raises(SceneFormatError) as err:
        load_scene(path)
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    assert peak < need // 4  # nothing of the scene's size was allocated
    assert str(err.value) == (f"{path}: needs 6.3 MB of memory to load 45,624 splats "
                              f"(SH degree 0), only 3.0 MB available")


def test_scene_too_big_cli_exit_2(shared_scenes):
    path = shared_file(shared_scenes, "ply/donut_sh0.ply")
    proc = subprocess.run([sys.executable, "-m", "splatgl", "info", str(path)], capture_output=True,
                          text=True, env={**__import__("os").environ, LIMIT_ENV: "1000000"})
    assert proc.returncode == 2
    assert proc.stderr.strip().splitlines() == [
        f"splatgl: error: {path}: needs 6.3 MB of memory to load 45,624 splats (SH degree 0), "
        "only 1.0 MB available"]


def _scene(n: int, degree: int) -> Scene:
    rng = np.random.default_rng(5)
    quats = rng.normal(size=(n, 4))
    quats[3] = 0.0  # degenerate: opacity 0, identity rotation
    return Scene(rng.normal(size=(n, 3)) + 100.0, quats, rng.normal(-3, 1, (n, 3)),
                 rng.normal(size=n), rng.normal(0, 0.3, (n, (degree + 1) ** 2, 3)))


@pytest.mark.parametrize("half_sh", [False, True])
def test_chunked_upload_equals_whole_scene_layout(ctx, monkeypatch, half_sh):
    monkeypatch.setattr(scene_buffers, "UPLOAD_ROWS", 1000)
    scene = _scene(2501, 2)  # 3 chunks, the last partial; odd count x 24 halves
    bufs = scene_buffers.SceneBuffers(ctx, scene, half_sh)
    try:
        n = scene.count
        got = {k: np.frombuffer(getattr(bufs, k).read(), np.float32).reshape(n, 4)
               for k in ("a", "q", "s", "dc")}
        np.testing.assert_array_equal(got["a"][:, :3], scene.relative_means)
        np.testing.assert_array_equal(got["a"][:, 3], scene.opacities)
        np.testing.assert_array_equal(got["q"], scene.rotations)
        np.testing.assert_array_equal(got["s"][:, :3], scene.scales)
        np.testing.assert_array_equal(got["dc"][:, :3], scene.sh[:, 0])
        dtype = np.float16 if half_sh else np.float32
        rest = np.frombuffer(bufs.sh.read(), dtype)[:n * 24]
        np.testing.assert_array_equal(rest, scene.sh[:, 1:].astype(dtype).ravel())
    finally:
        bufs.release()


def test_cull_data_from_scene_in_blocks_equals_whole_arrays():
    scene = _scene(2501, 0)
    data = CullData.from_scene(scene, block=700)
    whole = CullData(scene.relative_means, scene.scales.max(axis=1), scene.opacities)
    for name in ("xyz", "radius", "max_scale", "opacities", "alive", "faint"):
        np.testing.assert_array_equal(getattr(data, name), getattr(whole, name), name)
