"""benchmarks/frame_order.py (issue 40's llvmpipe target as a frame's order stage: the CPU
order against the device order) on a tiny real-data scene, one round: every JSON field there,
the transfer counters the issue bounds, and its one-line refusals."""

from __future__ import annotations

import importlib.util
import json
import sys
from pathlib import Path

import pytest

from splatgl.errors import SplatglError
from splatgl.order import kernels as cull_kernel

REPO = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def bench():
    """The benchmark script as a module (it imports its sibling ``_script``)."""
    folder = str(REPO / "benchmarks")
    sys.path.insert(0, folder)
    try:
        spec = importlib.util.spec_from_file_location("frame_order", REPO / "benchmarks" / "frame_order.py")
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
    finally:
        sys.path.remove(folder)
    return module


def test_views_and_frames_are_refused_in_one_line(bench, gl_renderer):
    """Bad --views and --frames: a SplatglError naming the option (the script prints one line)."""
    assert bench.check_views(" fisheye,orthographic ") == ("fisheye", "orthographic")
    with pytest.raises(SplatglError, match=r"^--views: ods is not a view \(expected some of "
                                           r"pinhole, fisheye, equirect, orthographic\)$"):
        bench.check_views("pinhole,ods")
    with pytest.raises(SplatglError, match=r"^--frames must be at least 1, got 0$"):
        bench.report(gl_renderer, (), 0, 64, 48, bench.VIEWS)


@pytest.mark.slow
def test_one_round_at_a_tiny_size(bench, gl_renderer, shared_scenes, tmp_path):
    """Every view's row: both orders' stage and frame times, their ratios, the stage split, the
    device order's frames identical and moving only uniforms up and the image back."""
    width, height = 64, 48
    seen = []
    doc = bench.report(gl_renderer, (3000,), 1, width, height, bench.VIEWS, cache=tmp_path,
                       start=lambda machine, load: seen.append("start"),
                       log=lambda row: seen.append(row["view"]))
    assert seen == ["start", *bench.VIEWS]
    json.loads(json.dumps(doc))   # plain JSON
    assert {"cpu", "simd", "cores", "gl_renderer", "cull"} <= set(doc["machine"])
    assert doc["machine"]["gl_renderer"] != "?"
    # the compiled cull where numba is installed (its module registered before the load)
    assert doc["machine"]["cull"] == ("compiled (numba)" if cull_kernel.installed() else "numpy")
    assert [len(doc["load_average"][k]) for k in ("start", "end")] == [3, 3]
    assert (doc["frames"], doc["width"], doc["height"], doc["interleaved"]) == (1, 64, 48, True)
    image = width * height * 16   # the float32 RGBA read back
    for row, view in zip(doc["rows"], bench.VIEWS):
        assert (row["splats"], row["view"]) == (3000, view)
        assert 0 < row["kept"] <= row["kept_gpu"] <= 2 * 3000   # the device keeps a superset
        assert row["identical_image"] is True and row["gpu_frame_device_order"] is True
        for key in ("exact_order_ms", "gpu_order_ms", "exact_frame_ms", "gpu_frame_ms"):
            assert row[key] > 0, key
        assert row["order_gpu_over_exact"] == pytest.approx(row["gpu_order_ms"] / row["exact_order_ms"])
        assert row["frame_gpu_over_exact"] == pytest.approx(row["gpu_frame_ms"] / row["exact_frame_ms"])
        assert set(row["exact_order_stages_ms"]) == {"cull", "sort", "upload"}
        for key in ("exact_frame_stages_ms", "gpu_frame_stages_ms"):
            assert set(row[key]) == {"cull", "sort", "upload", "prepass", "draw", "readback"}
        assert row["gpu_frame_stages_ms"]["upload"] == 0.0   # no order crosses the bus
        t = row["transfers"]
        assert set(t) == {"exact_order", "gpu_order", "exact_frame", "gpu_frame"}
        assert t["exact_order"]["upload_bytes"] >= 4 * row["kept"] // 2   # the order, 4 bytes a row
        assert t["exact_order"]["readback_bytes"] == t["gpu_order"]["readback_bytes"] == 0
        assert 0 < t["gpu_order"]["upload_bytes"] <= 4096   # the command and uniforms
        assert 0 < t["gpu_frame"]["upload_bytes"] <= 4096
        assert t["gpu_frame"]["readback_bytes"] == image
        assert t["exact_frame"]["readback_bytes"] >= image
