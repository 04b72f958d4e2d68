"""The scale and LOD benchmarks on tiny real-data scenes: every figure present and sane, the
device sort identical to the CPU sort, sizes parsed, slopes fitted exactly on a power law."""

from __future__ import annotations

import pytest

from splatgl.measure.bench.lod_bench import bench_lod, summary
from splatgl.measure.bench.scale import ScaleOptions, measure_file, scene_file
from splatgl.measure.bench.scale import parse_sizes
from splatgl.measure.bench.scale_report import loglog_slope, table
from splatgl.errors import SplatglError


def test_parse_sizes():
    assert parse_sizes("0.1M,300k,6M", (), "--sizes") == (100_000, 300_000, 6_000_000)
    assert parse_sizes(None, (5,), "--sizes") == (5,)
    assert parse_sizes("none", (5,), "--sizes") == ()
    with pytest.raises(SplatglError, match="--sizes: 'abc' is not a size"):
        parse_sizes("abc", (), "--sizes")


def test_loglog_slope_of_a_power_law():
    xs = [1e5, 3e5, 1e6, 6e6]
    assert loglog_slope(xs, [2.0 * x ** 0.75 for x in xs]) == pytest.approx(0.75, abs=1e-9)
    assert loglog_slope([1e5], [1.0]) is None


@pytest.fixture(scope="module")
def tiny_file(tmp_path_factory, shared_scenes):
    return scene_file(3000, 0, tmp_path_factory.mktemp("scale"))


def test_measure_file_rows(tiny_file):
    opts = ScaleOptions(sizes=(3000,), sh3_sizes=(), resolutions=((64, 48),), frames=1, tile_max=3000)
    (row,) = measure_file(tiny_file, opts)
    assert row.splats == 3000 and row.sh_degree == 0 and (row.width, row.height) == (64, 48)
    assert row.gpu_bytes_per_splat == 64.0  # 4 vec4 at SH degree 0
    assert row.decoded_mb == pytest.approx(3000 * 14 * 4 / 1e6)
    assert row.gpu_sort_identical is True
    assert row.compact_bytes_per_splat == 32.0  # two uvec4 (splatgl/gl/storage.py)
    assert 60.0 < row.compact_psnr < 200.0  # changed, within the stated cost (tests/gl/test_storage.py)
    assert 0 < row.visible <= 3000 and row.tile_frame_ms > 0 and row.quad_frame_ms > 0
    assert set(row.stages_ms) == {"cull", "sort", "upload", "prepass", "draw", "readback"}
    from splatgl.order import kernels as cull_kernel

    assert row.cull_compiled is cull_kernel.installed()  # loaded before the timed frames
    assert "3,000" in table([row])
    assert ("cull: the compiled kernel (numba)" if row.cull_compiled else "cull: NumPy") in table([row])


def test_lod_bench_rows(tiny_file):
    rows = bench_lod(tiny_file, 64, 48, 3, [1.0], [500], log=lambda m: None, bands=(2.0, 1.0))
    assert {(r.path, r.config) for r in rows} == {(p, c) for p in ("orbit", "fly")
                                                  for c in ("T=1px", "T=1px hard", "budget=500")}
    assert all(r.cut_nodes <= 500 for r in rows if r.config == "budget=500")
    fly = [r for r in rows if r.path == "fly" and r.config == "T=1px"]
    assert fly[0].distance == pytest.approx(6.0) and fly[-1].distance == pytest.approx(0.5)
    assert fly[0].cut_nodes < fly[-1].cut_nodes  # far: coarse, close: fine
    assert fly[0].pop_max is None and fly[1].pop_max >= fly[1].pop_mean >= 0
    assert fly[1].full_change_max > 0 and fly[1].cut_change_max is None  # coarse: not drawn
    s = summary(rows)
    assert len(s) == 6 and all(x["min_ssim"] > 0 for x in s)
    assert all(x["pop_max"] is not None and x["full_change_mean"] > 0 for x in s)
    assert all(x["cut_change_max"] is None for x in s)


def test_lod_bench_fine_paths(tiny_file):
    rows = bench_lod(tiny_file, 64, 48, 3, [1.0], [], log=lambda m: None, paths="fine")
    fly = [r for r in rows if r.path == "fly-fine"]
    assert [r.distance for r in fly] == pytest.approx([6.0, 6.0 * 0.97, 6.0 * 0.97 ** 2])
    assert {r.path for r in rows} == {"fly-fine", "orbit-fine"}
    assert all(r.cut_change_max >= r.cut_change_mean >= 0 for r in rows if r.frame > 0)


def test_lod_bench_switch_path_crosses_the_switch_to_the_leaves(tiny_file):
    """The switch path is centred on the distance where the cut gives way to the leaves: the
    frames before it draw a cut, the middle frame and those after draw the leaves, and the
    middle frame's cut change is the switch's own pop (the change against the previous frame's
    cut at the same camera), the frames after it none."""
    rows = bench_lod(tiny_file, 64, 48, 6, [1.0], [], log=lambda m: None, paths="switch")
    assert {r.path for r in rows} == {"fly-switch"}
    d = [r.distance for r in rows]
    assert d == pytest.approx([d[3] * 0.97 ** (i - 3) for i in range(6)])
    assert [r.leaves for r in rows] == [False] * 3 + [True] * 3
    assert rows[3].cut_change_max > 0 and rows[3].cut_ms > 0
    assert all(r.cut_change_max == 0.0 for r in rows[4:])
