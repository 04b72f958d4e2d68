"""``--memory`` bounds a streamed frame's whole process (issue 41 item 3): the budget's split
(splatgl.lod.budget.stream_plan), the cut capped by it (splatgl.lod.stream_cut), abandoned
trial cuts (splatgl.lod.cut.CutTooLarge) and the frames drawn under the cap."""

from __future__ import annotations

import numpy as np
import pytest

from splatgl.cli import main
from splatgl.errors import SplatglError
from splatgl.lod.budget import CACHE_SHARE, StreamPlan, stream_plan
from splatgl.lod.cut import CutData, CutTooLarge, select_cut_weights
from splatgl.lod.cut_budget import ABORT_FACTOR, select_cut_budget
from splatgl.lod.frames import LodFrames
from splatgl.lod.io import read_lod
from splatgl.lod.lazy import LazyLod
from splatgl.lod.selection import LodSettings
from splatgl.lod.stream_cut import SPHERE_PAGES_PER_SPLAT, choose_cut
from splatgl.lod.stream_frames import StreamFrames
from splatgl.scene.settings import EarlyStop, RenderSettings
from helpers import stream_camera, stream_lod_file

# Early termination off: these tests compare the streamed and in-memory images bit for bit.
SETTINGS = RenderSettings(near=0.01, early_stop=EarlyStop.OFF)


_lod, _camera = stream_lod_file, stream_camera   # the streaming tests' scene and views


def _plan(cap: int, cache: int = 1 << 20, per_splat: int = 100) -> StreamPlan:
    """Nothing else held: ``cache`` bytes of chunks, a frame of at most ``cap`` splats."""
    return StreamPlan(budget=cache + cap * per_splat, held=0, reserve=0, cache=cache,
                      frame=cap * per_splat, per_splat=per_splat)



def test_the_budget_is_split_between_chunks_and_frame():
    """What the process holds and the draw's reserve come off first; the chunk cache takes
    CACHE_SHARE of the rest (at least what it needs), the frame the remainder; the cap is the
    frame's bytes over a splat's; too little is one line naming what would do."""
    plan = stream_plan(2 << 30, 300, cache_need=10 << 20, held=200 << 20, reserve=300 << 20)
    working = (2 << 30) - (500 << 20)
    assert plan.cache == int(CACHE_SHARE * working) and plan.frame == working - plan.cache
    assert plan.cap == plan.frame // 300
    assert plan.held + plan.reserve + plan.cache + plan.frame == 2 << 30
    small = stream_plan(600 << 20, 300, cache_need=200 << 20, held=200 << 20, reserve=100 << 20)
    assert small.cache == 200 << 20 and small.frame == 100 << 20
    with pytest.raises(SplatglError, match=r"^--memory 400 MiB is too small to stream this "
                                           r"level of detail: this process holds 200 MiB, .* "
                                           r"give at least"):
        stream_plan(400 << 20, 300, cache_need=100 << 20, held=200 << 20, reserve=100 << 20)


def test_a_cut_past_max_nodes_is_abandoned_numpy_and_compiled_alike(tmp_path, compiled_kernels):
    """``max_nodes``: CutTooLarge before the level that would pass it (the same count from the
    NumPy and compiled cuts), the same cut where it fits; a budget's search (abandoning trials
    at ABORT_FACTOR times the budget) finds the same cut both ways."""
    from splatgl.order import kernels as cull_kernel

    tree = read_lod(_lod(tmp_path))
    data = CutData.from_tree(tree)
    camera = _camera(1.5)
    full, _ = select_cut_weights(data, camera, 1.0, 2.0)
    kerns = [None]
    if cull_kernel.installed():
        kerns.append(cull_kernel.kernel(wait=True))
    counts = []
    for kern in kerns:
        with pytest.raises(CutTooLarge) as info:
            select_cut_weights(data, camera, 1.0, 2.0, kern=kern, max_nodes=full.size // 3)
        counts.append(info.value.nodes)
        rows, _ = select_cut_weights(data, camera, 1.0, 2.0, kern=kern, max_nodes=full.size * 4)
        assert np.array_equal(rows, full)
        budget = full.size // 10
        got = select_cut_budget(data, camera, budget, 1.0, 2.0, kern=kern)
        assert got[0].size <= budget < full.size // ABORT_FACTOR
        if kern is not None:
            want = select_cut_budget(data, camera, budget, 1.0, 2.0)
            assert np.array_equal(got[0], want[0]) and got[2] == want[2]
            assert np.array_equal(got[1], want[1])
    assert len(set(counts)) == 1 and counts[0] > full.size // 3


def test_capped_frames_are_the_in_memory_budget_frames(tmp_path):
    """A view whose cut asks for more than the frame holds draws the finest cut within the
    cap: exactly the in-memory LOD's frame with ``--lod-budget cap``; it is said once, with the
    numbers; a view that fits is not capped."""
    path = _lod(tmp_path)
    tree = read_lod(path)
    cap = 200
    cams = [_camera(1.5), _camera(2.0, 0.4)]
    with LodFrames(tree, SETTINGS, LodSettings(budget=cap)) as ref, \
            StreamFrames(path, SETTINGS, LodSettings(), 1 << 20, chunk_rows=64,
                         framing=tree.nodes, plan=_plan(cap)) as st:
        for a, b in zip(ref.render_many(None, cams), st.render_many(None, cams)):
            assert np.array_equal(a, b)
            assert st.last_cut_nodes <= cap
        assert st.capped.startswith("the memory bound made the cut coarser than "
                                    "--lod-threshold 1 px asked: ")
        assert f"(the frame holds at most {cap:,} splats)" in st.capped
        assert "2 of 2 views capped" in st.summary()
        assert st.resident.stats.rows_read > 0   # chunks needed for a few rows: read alone
    with StreamFrames(path, SETTINGS, LodSettings(), 1 << 20, chunk_rows=64,
                      framing=tree.nodes, plan=_plan(cap)) as st:
        st.render_view(_camera(400.0))   # far: a cut of a few nodes
        assert st.capped is None and "capped" not in st.summary()


def test_a_capped_budget_is_the_smaller_budget(tmp_path):
    """--lod-budget above the cap: the cap's cut, said; below it: the budget's own."""
    path = _lod(tmp_path)
    with LazyLod(path) as lazy:
        camera = _camera(1.5)
        capped = choose_cut(lazy, camera, LodSettings(budget=1000), cap=150)
        assert capped.rows.size <= 150 and "--lod-budget 1,000 asked" in capped.capped
        own = choose_cut(lazy, camera, LodSettings(budget=100), cap=150)
        want = select_cut_budget(lazy.cut_data, camera, 100, 1.0, 2.0)
        assert own.capped is None and np.array_equal(own.rows, want[0])


def test_a_path_holds_a_flat_bound(tmp_path):
    """A fly-in under a small frame: every frame's gathered nodes stay within the cap (the
    bytes the frame model counts), and the sphere pages kept between frames within theirs,
    frame after frame (not the process's RSS: the bound on what the frame gathers)."""
    path = _lod(tmp_path)
    cap = 250
    plan = _plan(cap, cache=64 << 10)
    cams = [_camera(6.0 - 0.7 * i, 0.1 * i) for i in range(7)]
    with StreamFrames(path, SETTINGS, LodSettings(), 1 << 20, chunk_rows=32,
                      plan=plan) as st:
        row = st.resident.chunks.row_bytes
        gathered, spheres = [], []
        for camera in cams:
            st.render_view(camera)
            gathered.append(st.last_gathered_bytes)
            spheres.append(st.lazy.sphere_bytes)
        assert max(gathered) <= cap * row and st.capped_views >= 3
        assert max(spheres) <= SPHERE_PAGES_PER_SPLAT * 16 * cap
        assert st.resident.stats.peak_bytes <= 64 << 10


def test_render_says_once_when_the_memory_bound_coarsened_the_cut(tmp_path, capsys, monkeypatch):
    """``render --memory`` and ``render --path --memory``: one line with the numbers when the
    bound made the cut coarser, and --timings counts the views (a splat made to cost 1 MiB so
    that a realistic budget caps this small scene)."""
    from splatgl.lod import stream_cut

    monkeypatch.setattr(stream_cut, "per_splat", lambda lazy, storage=None: 16 << 20)
    path = _lod(tmp_path)
    args = ["--memory", "6G", "--width", "96", "--height", "64", "--lod-threshold", "0.25",
            "--timings"]
    assert main(["render", str(path), "-o", str(tmp_path / "a.png"), *args]) == 0
    out = capsys.readouterr().out
    lines = [line for line in out.splitlines() if line.startswith("the memory bound")]
    assert len(lines) == 1 and "coarser than --lod-threshold 0.25 px asked" in lines[0]
    assert "1 of 1 views capped" in out and "capped the memory bound" not in out   # said once
    assert main(["render", str(path), "--path", "orbit:3", "-o", str(tmp_path / "f%02d.png"),
                 *args]) == 0
    out = capsys.readouterr().out
    assert sum(line.startswith("the memory bound") for line in out.splitlines()) == 1
    assert "3 of 3 views capped" in out


def test_spheres_read_mapped_or_by_pages_alike_and_kept_nowhere(tmp_path):
    """A streamed cut's spheres: gathered from the mapped file (pages dropped after) or read by
    pages where it cannot be mapped, the same values; nothing kept between calls beyond the
    last read; the cut over them is the in-memory tree's (the candidates alone)."""
    path = _lod(tmp_path)
    tree = read_lod(path)
    with LazyLod(path) as mapped, LazyLod(path) as paged:
        paged._mapped = False
        rows = np.unique(np.random.default_rng(1).integers(0, int(mapped.offsets[-1]), 700))
        for a, b in zip(mapped.spheres(rows), paged.spheres(rows)):
            assert np.array_equal(a, b)
        assert mapped._mapped and mapped.sphere_bytes == 0
        a, b = mapped.nodes(rows), paged.nodes(rows)   # the node rows alike
        for f in ("means", "quats", "log_scales", "opacity_logits", "sh"):
            assert np.array_equal(getattr(a, f), getattr(b, f))
        camera = _camera(2.0, 0.3)
        want = select_cut_weights(CutData.from_tree(tree), camera, 1.0, 2.0)
        for lazy in (mapped, paged):
            got = select_cut_weights(lazy.cut_data, camera, 1.0, 2.0)
            assert np.array_equal(got[0], want[0]) and np.array_equal(got[1], want[1])


def test_bench_memory_reports_the_cap(tmp_path, capsys, monkeypatch):
    """``bench SCENE.lod.ply --memory``: the frame's cap and the capped line in the figures."""
    import json

    from splatgl.lod import stream_cut

    monkeypatch.setattr(stream_cut, "per_splat", lambda lazy, storage=None: 64 << 20)
    path = _lod(tmp_path)
    assert main(["bench", str(path), "--memory", "12G", "--quick", "--frames", "2", "--width",
                 "192", "--height", "128", "--json", "-"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert 100 <= report["frame_cap"] < 200 and report["cut_nodes_median"] <= report["frame_cap"]
    assert report["capped"].startswith("the memory bound made the cut coarser")


@pytest.mark.parametrize("slice_rows", [None, 7])
def test_the_compiled_cut_reads_the_files_mapping_and_cuts_alike(tmp_path, compiled_kernels,
                                                                 monkeypatch, slice_rows):
    """The compiled cut of a lazily read tree (its spheres straight from the file's mapping,
    the anchor taken off in the kernel, a level's candidates in slices of rows) gives the NumPy
    lazy cut's rows and weight bits and the in-memory tree's, abandons a trial at the same
    count, drives the budget's search to the same cut and threshold."""
    if compiled_kernels is None:
        pytest.skip("numba is not installed (the fast extra)")
    from splatgl.cameras.camera import Camera
    from splatgl.cameras.poses import look_at

    path = _lod(tmp_path)
    memory = CutData.from_tree(read_lod(path))
    pose = look_at(np.array([0.3, 0.2, 1.2]), np.zeros(3))
    lenses = (Camera.fisheye(96, 64, 190.0, pose), Camera.orthographic(96, 64, 40.0, pose))
    with LazyLod(path) as lazy:
        assert lazy.cut_data.columns() is not None
        if slice_rows is not None:   # a few parents a slice: every level in many slices
            monkeypatch.setattr(type(lazy.cut_data.centres), "slice_rows", slice_rows)
        for camera in (_camera(1.5), _camera(2.0, 0.4), _camera(0.2), *lenses):
            for t, band in ((1.0, 1.0), (1.0, 2.0), (3.0, 2.0), (float("inf"), 1.0)):
                lazy.trim_spheres(0)   # no spheres kept from the last cut: all counted
                read = lazy.bytes_read
                want = select_cut_weights(lazy.cut_data, camera, t, band)
                read = lazy.bytes_read - read, lazy.bytes_read
                for data in (lazy.cut_data, memory):
                    got = select_cut_weights(data, camera, t, band, kern=compiled_kernels)
                    if data is lazy.cut_data:   # the same spheres tested, counted alike
                        assert lazy.bytes_read - read[1] == read[0]
                    assert np.array_equal(got[0], want[0])
                    assert (got[1] is None) == (want[1] is None)
                    if want[1] is not None:
                        assert np.array_equal(got[1].view(np.uint32), want[1].view(np.uint32))
            full = select_cut_weights(lazy.cut_data, camera, 1.0, 2.0)[0]
            if full.size > 10:
                counts = []
                for kern in (None, compiled_kernels):
                    with pytest.raises(CutTooLarge) as info:
                        select_cut_weights(lazy.cut_data, camera, 1.0, 2.0, kern=kern,
                                           max_nodes=full.size // 3)
                    counts.append(info.value.nodes)
                assert counts[0] == counts[1]
                budget = max(1, full.size // 5)
                a = select_cut_budget(lazy.cut_data, camera, budget, 1.0, 2.0)
                b = select_cut_budget(lazy.cut_data, camera, budget, 1.0, 2.0,
                                      kern=compiled_kernels)
                assert np.array_equal(a[0], b[0]) and a[2] == b[2]
                assert np.array_equal(a[1], b[1])


def test_a_large_trees_streamed_cut_waits_for_the_compiled_cut(tmp_path, monkeypatch,
                                                                compiled_kernels):
    """Past COMPILED_CUT_NODES nodes a streamed view's cut waits for the compiled kernels (a
    NumPy budget search there takes seconds); a smaller tree's takes what is loaded, and the
    kernel policy "off" gives NumPy's everywhere."""
    from splatgl.lod import stream_cut
    from splatgl.order import kernels

    path = _lod(tmp_path)
    with LazyLod(path) as lazy:
        if compiled_kernels is not None:
            monkeypatch.setattr(stream_cut, "COMPILED_CUT_NODES", 10)
            assert stream_cut.cut_kernels(lazy) is compiled_kernels
            monkeypatch.setattr(stream_cut, "COMPILED_CUT_NODES", int(lazy.offsets[-1]))
            assert stream_cut.cut_kernels(lazy) is compiled_kernels   # loaded already
        monkeypatch.setattr(stream_cut, "COMPILED_CUT_NODES", 10)
        kernels.set_policy("off")
        try:
            assert stream_cut.cut_kernels(lazy) is None
        finally:
            kernels.set_policy("auto")
