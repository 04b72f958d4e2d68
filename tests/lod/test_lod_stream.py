"""Streaming a level of detail under a memory budget (issue 41 item 3): splatgl.lod.stream
(the resident set of chunks) and splatgl.lod.stream_frames (exact frames from it)."""

from __future__ import annotations

import threading
import time

import numpy as np
import pytest

from splatgl.cli import main
from splatgl.errors import SplatglError
from splatgl.lod.build import level_offsets
from splatgl.lod.frames import LodFrames
from splatgl.lod.io import read_lod
from splatgl.lod.lazy import LazyLod
from splatgl.lod.selection import LodSettings
from splatgl.lod.budget import StreamPlan
from splatgl.lod.stream import ResidentSet
from splatgl.lod.stream_frames import StreamFrames
from splatgl.scene.splats import Scene
from splatgl.scene.settings import EarlyStop, RenderSettings
from helpers import GatedChunks, stream_camera, stream_lod_file

# Early termination off: its batches stop on the streamed and the in-memory node lists at
# slightly different points (up to 9e-5 on 1.6% of pixels where `auto` means `on`, as on a GPU),
# and these tests compare the two lists' images bit for bit.
SETTINGS = RenderSettings(near=0.01, early_stop=EarlyStop.OFF)


def cache_plan(cache: int, cap: int | None = None, per_splat: int = 100):
    """A stream plan of ``cache`` bytes of chunks and a frame of at most ``cap`` splats (None:
    not capped), with nothing else held (tests: a tiny scene under budgets smaller than it)."""
    frame = (1 << 40) if cap is None else cap * per_splat
    return StreamPlan(budget=cache + frame, held=0, reserve=0, cache=cache, frame=frame,
                      per_splat=per_splat)


_lod, _camera = stream_lod_file, stream_camera   # the streaming tests' scene and views


@pytest.mark.parametrize("lod", [LodSettings(), LodSettings(threshold_px=2.0, band=1.0),
                                 LodSettings(budget=300)], ids=["blend", "hard", "budget"])
def test_streamed_frames_are_the_in_memory_lod_frames(tmp_path, lod):
    """Far and middle views (cuts of coarse nodes) and a budget's cut: identical images, with
    chunks of 64 rows under a budget smaller than the file (so chunks are evicted on the way)."""
    path = _lod(tmp_path)
    tree = read_lod(path)
    cams = [_camera(8.0), _camera(3.0, 0.5), _camera(6.0, -1.0)]
    with LodFrames(tree, SETTINGS, lod) as ref, \
            StreamFrames(path, SETTINGS, lod, 96 << 10, chunk_rows=64, framing=tree.nodes,
                         plan=cache_plan(96 << 10)) as st:
        for a, b in zip(ref.render_many(None, cams), st.render_many(None, cams)):
            assert np.array_equal(a, b)
        assert st.resident.stats.peak_bytes <= 96 << 10
        assert st.resident.stats.loaded > 0


def test_streamed_close_view_draws_the_leaves_in_view(tmp_path):
    """Where the in-memory cut switches to every leaf, the stream draws the leaves whose sphere
    is in view: the same image but for splats just outside the frustum (guard band)."""
    path = _lod(tmp_path)
    tree = read_lod(path)
    with LodFrames(tree, SETTINGS, LodSettings()) as ref, \
            StreamFrames(path, SETTINGS, LodSettings(), 1 << 20, chunk_rows=64,
                         framing=tree.nodes, plan=cache_plan(1 << 20)) as st:
        a, b = ref.render_view(_camera(1.5)).rgba, st.render_view(_camera(1.5)).rgba
        assert st.last_cut_nodes < tree.level_size(0)
        assert np.abs(a - b).max() < 1e-3


def test_streamed_frames_agree_with_the_node_scenes_own_anchor(tmp_path):
    """Untouched in-memory LOD (its node scene's anchor): float32 rounding apart."""
    path = _lod(tmp_path)
    tree = read_lod(path)
    with LodFrames(tree, SETTINGS, LodSettings()) as ref, \
            StreamFrames(path, SETTINGS, LodSettings(), 1 << 20, chunk_rows=64,
                         plan=cache_plan(1 << 20)) as st:
        a, b = ref.render_view(_camera(5.0)).rgba, st.render_view(_camera(5.0)).rgba
        assert np.abs(a - b).max() < 1e-3


def test_a_path_evicts_least_recently_used_chunks_under_the_budget(tmp_path):
    """A fly-through under a budget of a fraction of the file: every chunk load is checked
    against the budget (instrumented), chunks are evicted, the frames stay exact."""
    path = _lod(tmp_path)
    tree = read_lod(path)
    budget = 64 << 10
    cams = [_camera(4.0 - 0.4 * i, -1.0 + 0.25 * i) for i in range(8)]
    with LodFrames(tree, SETTINGS, LodSettings(band=1.0)) as ref, \
            StreamFrames(path, SETTINGS, LodSettings(band=1.0), budget, chunk_rows=32,
                         framing=tree.nodes, plan=cache_plan(budget)) as st:
        res = st.resident
        seen = []
        load = res.chunks.load

        def checked(chunk):
            seen.append(res.stats.resident_bytes + res._reserved)
            return load(chunk)

        res.chunks.load = checked
        for a, b in zip(ref.render_many(None, cams), st.render_many(None, cams)):
            assert np.array_equal(a, b)
        assert seen and max(seen) <= budget
        assert res.stats.peak_bytes <= budget and res.stats.resident_bytes <= budget
        assert res.stats.evicted > 0
        whole = sum(res.chunks.estimate(c) for c in range(res.chunks.count))
        assert whole > 2 * budget


class _FakeChunks:
    """Chunks of 4 rows of a tree of 64 leaves (branching 4); loads wait for ``gate``."""

    rows = 4

    def __init__(self):
        self.offsets = level_offsets(64, 4)
        self.nodes = int(self.offsets[-1])
        self.count = -(-self.nodes // self.rows)
        self.gate = threading.Event()
        self.loads = []

    def estimate(self, chunk):
        return 100

    hold_top = False   # the top levels' chunks wait for the gate too

    def load(self, chunk):
        if chunk < self.count - 2 or self.hold_top:   # the top levels' chunks come at once
            self.gate.wait(5)
        self.loads.append(chunk)
        n = min(self.rows, self.nodes - chunk * self.rows)
        z = np.zeros((n, 3), np.float32)
        q = np.tile(np.float32([1, 0, 0, 0]), (n, 1))
        return Scene(z, q, z, np.zeros(n, np.float32), np.zeros((n, 1, 3), np.float32))


def test_viewer_cut_stands_in_ancestors_then_refines():
    """Headless, a fake loader: a cut of leaves not resident is drawn as the nearest resident
    ancestors (weights summed, at most 1); as chunks arrive ``on_loaded`` asks for a redraw and
    the cut becomes the exact one."""
    chunks = _FakeChunks()
    redraws = threading.Semaphore(0)
    res = ResidentSet(chunks, 10_000, chunks.offsets, 4)
    try:
        res.load_pinned()   # levels 2 and 3 (rows 80..84): chunks 20, 21
        res.on_loaded = redraws.release
        leaves = np.arange(0, 16)
        rows, weights, complete = res.resident_cut(leaves, None)
        assert not complete and weights is None
        # leaves 0..15 -> level 1 nodes 64..67 (chunk 16, not resident) -> level 2 node 80
        assert rows.tolist() == [80]
        half = np.full(16, 0.5, np.float32)
        rows, weights, complete = res.resident_cut(leaves, half)
        assert rows.tolist() == [80] and weights.tolist() == [1.0] and not complete
        chunks.gate.set()
        for _ in range(4):   # the leaves' 4 chunks, requested above
            assert redraws.acquire(timeout=5)
        rows, weights, complete = res.resident_cut(leaves, None)
        assert complete and rows.tolist() == leaves.tolist()
    finally:
        res.close()


def test_viewer_cut_before_the_top_levels_arrive_draws_nothing_for_them():
    """The pinned top levels' loads held back: a cut whose nodes have no resident ancestor yet
    draws nothing for them (it raised "the top level ... is not resident": the 100M flight's
    first frame), requests the chunks, and completes once they arrive."""
    chunks = _FakeChunks()
    chunks.hold_top = True
    res = ResidentSet(chunks, 10_000, chunks.offsets, 4)
    try:
        cut = np.concatenate([np.arange(16, 32), [81, 84]])   # leaves, a level-2 node, the root
        rows, weights, complete = res.resident_cut(cut, None)
        assert not complete and rows.size == 0 and weights is None
        chunks.gate.set()
        end = time.perf_counter() + 10
        while not (got := res.resident_cut(cut, None))[2] and time.perf_counter() < end:
            time.sleep(0.005)
        assert got[2] and got[0].tolist() == cut.tolist() and got[1] is None
    finally:
        res.close()


def test_load_pinned_keeps_a_small_last_chunk(tmp_path):
    """The top levels' chunks are loaded whole and kept, the last one too when it has few rows
    (the gather read it alone and did not keep it: at 100M the root's chunk has 346 of 4096
    rows, and the first resident cut found no top level)."""
    from splatgl.lod.stream import LazyChunks

    path = _lod(tmp_path)
    with LazyLod(path) as lazy:
        chunks = LazyChunks(lazy, 32)   # 4001 nodes: the last chunk holds the root alone
        assert chunks.nodes - (chunks.count - 1) * 32 == 1
        with ResidentSet(chunks, 1 << 22, lazy.offsets, lazy.branching) as res:
            res.load_pinned()
            assert all(res.held(c) is not None for c in sorted(res._pinned))
            top = np.arange(int(lazy.offsets[-3]), chunks.nodes)
            rows, _, complete = res.resident_cut(top, None)
            assert complete and rows.tolist() == top.tolist()


def test_close_stops_the_loaders_promptly():
    """Loads not started are cancelled; a frame waiting for them is interrupted."""
    chunks = _FakeChunks()
    res = ResidentSet(chunks, 10_000, chunks.offsets, 4, threads=1)
    res.request(range(10))
    res.close()
    chunks.gate.set()
    with pytest.raises((KeyboardInterrupt, SplatglError)):
        res.gather(np.arange(0, 40))
    assert len(chunks.loads) <= 1


def test_a_budget_too_small_is_one_line(tmp_path):
    path = _lod(tmp_path)
    with pytest.raises(SplatglError, match="--memory .* too small to stream"):
        StreamFrames(path, SETTINGS, LodSettings(), 1000, chunk_rows=64)


def _png(path):
    from splatgl.imagefiles.images import read_image
    return read_image(path)


def test_render_and_path_stream_with_memory(tmp_path, capsys):
    """``render --memory`` and ``render --path --memory``: the streamed frames (the API's, same
    framing proxy), resident memory and chunks under --timings; the frame record names the
    file by its spheres' digest (never read whole)."""
    path = _lod(tmp_path)
    code = main(["render", str(path), "-o", str(tmp_path / "a.png"), "--memory", "1.5G",
                 "--width", "96", "--height", "64", "--timings"])
    out = capsys.readouterr().out
    assert code == 0 and "level of detail streamed under 1.5 GiB" in out
    assert "streaming resident" in out and "loaded" in out and "evicted" in out
    # the summary counts the cut drawn, of the scene's splats (it gave the scene's alone)
    import re
    from splatgl.formats import load_scene

    cut = int(re.search(r"cut_nodes ([\d,]+)", out).group(1).rstrip(",").replace(",", ""))
    count = load_scene(path).count
    assert f"(96x64, a {cut:,}-splat cut of {count:,}, " in out, out
    code = main(["render", str(path), "--path", "orbit:3", "-o", str(tmp_path / "f%02d.png"),
                 "--memory", "1.5G", "--width", "96", "--height", "64", "--timings"])
    out = capsys.readouterr().out
    assert code == 0 and "wrote 3 frames" in out and "streaming: resident" in out
    assert (tmp_path / "f02.png").exists()


@pytest.mark.parametrize("argv, message", [
    (["--memory", "1.2M", "--renderer", "tile"], "render through the quad path"),
    (["--memory", "2X"], "--memory: expected a size"),
    (["--memory", "2K"], "--memory 2 KiB is too small to stream"),
    (["--memory", "1M", "--path", "orbit:2", "--workers", "2"], "--memory streams a path's frames "
                                                                "in one process"),
])
def test_render_memory_refusals_are_one_line(tmp_path, capsys, argv, message):
    path = _lod(tmp_path)
    out = tmp_path / ("f%02d.png" if "--path" in argv else "a.png")
    assert main(["render", str(path), "-o", str(out), "--width", "96", "--height", "64", *argv]) == 2
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1 and not (tmp_path / "a.png").exists()


def test_render_memory_needs_a_level_of_detail(tmp_path, capsys):
    _lod(tmp_path)
    assert main(["render", str(tmp_path / "s.ply"), "-o", str(tmp_path / "a.png"),
                 "--memory", "1M"]) == 2
    assert "not a level-of-detail file" in capsys.readouterr().err


_Gated = GatedChunks


def test_streamed_scene_draws_what_is_resident_then_the_exact_cut(tmp_path):
    """The viewer's scene: a close view first draws coarse stand-ins (fewer nodes, not
    complete), each chunk that arrives bumps the generation (the viewer redraws), and at the
    end the scene is the exact cut's (the one a screenshot waits for)."""
    from splatgl.lod.stream import LazyChunks
    from splatgl.lod.stream_view import StreamedScene

    path = _lod(tmp_path)
    with LazyLod(path) as lazy:
        chunks = _Gated(LazyChunks(lazy, 64))
        changes = threading.Semaphore(0)
        stream = StreamedScene(path, LodSettings(threshold_px=2.0, band=1.0), 1 << 20,
                               on_change=changes.release, chunks=chunks, plan=cache_plan(1 << 20))
        try:
            chunks.gated = True
            camera = _camera(3.0, 0.5)
            first = stream.scene_for(camera, SETTINGS)
            assert not stream.complete and "refining" in stream.summary()
            assert stream.scene_for(camera, SETTINGS) is first   # nothing new: the same upload
            chunks.gate.set()
            for _ in range(200):
                if changes.acquire(timeout=5) and (
                        stream.scene_for(camera, SETTINGS) is not None and stream.complete):
                    break
            assert stream.complete and stream.generation > 0
            last = stream.scene_for(camera, SETTINGS)
            exact = stream.exact_scene(camera, SETTINGS)
            assert last.count > first.count and np.array_equal(last.means, exact.means)
            assert "resident" in stream.summary() and "refining" not in stream.summary()
        finally:
            stream.close()


@pytest.mark.window
def test_view_memory_window_refines_and_screenshots(xvfb_display, tmp_path):
    """One short window: ``view --memory``'s scene in the viewer; frames are drawn again as
    chunks arrive until the cut is complete; the status panel shows resident memory; F12 waits
    for the chunks and writes the screenshot."""
    from splatgl.errors import ContextError
    from splatgl.lod.stream_view import StreamedScene
    from splatgl.viewer.app import Viewer, ViewerOptions
    from splatgl.viewer.screenshot import take_screenshot

    path = _lod(tmp_path)
    stream = StreamedScene(path, LodSettings(), 1 << 20, chunk_rows=64, plan=cache_plan(1 << 20))
    options = ViewerOptions(visible=True, screenshot_dir=tmp_path, render_args=(str(path),),
                            vsync=False, target_fps=0.0, stream=stream)
    try:
        try:
            v = Viewer(stream.framing, SETTINGS, _camera(3.0, 0.5), options=options)
        except ContextError as exc:
            pytest.skip(f"no OpenGL 4.3+ window context on Xvfb: {exc}")
        with v:
            assert v.step()
            for _ in range(100):
                if stream.complete:
                    break
                threading.Event().wait(0.02)
                v.step()
            assert stream.complete
            assert "resident" in v._status(v.camera()).message
            png, _ = take_screenshot(v)
            assert png.exists()
    finally:
        stream.close()


def test_eval_memory_scores_the_streamed_views(tmp_path, capsys):
    """``eval --memory``: each view rendered from the streamed level of detail (the in-memory
    LOD's frames as the photographs: the same images to float32 rounding), resident memory
    and chunks printed."""
    from splatgl.datasets import colmap
    from splatgl.datasets.named_camera import NamedCamera
    from splatgl.imagefiles.images import write_image

    path = _lod(tmp_path)
    root = tmp_path / "data"
    (root / "images").mkdir(parents=True)
    views = [NamedCamera(f"v{i}.png", _camera(4.0 + i, 0.3 * i)) for i in range(3)]
    with LodFrames(read_lod(path), RenderSettings(), LodSettings()) as ref:
        for view in views:
            rgba = ref.render_view(view.camera).rgba
            write_image(root / "images" / view.name, np.concatenate(
                [np.clip(rgba[..., :3], 0, 1), np.ones_like(rgba[..., :1])], -1), 16)
    colmap.write_colmap(root / "sparse" / "0", views)
    code = main(["eval", str(path), "--dataset", str(root), "--memory", "1.5G",
                 "--json", str(tmp_path / "s.json")])
    out, err = capsys.readouterr()
    assert code == 0 and "streaming: resident" in out, err
    import json
    report = json.loads((tmp_path / "s.json").read_text())
    assert report["mean"]["psnr"] > 60
    assert main(["eval", str(path), "--dataset", str(root), "--memory", "1M", "--renderer",
                 "tile"]) == 2
    assert "--memory streams a level of detail through the quad path" in capsys.readouterr().err


def test_bench_memory_times_a_streamed_orbit(tmp_path, capsys):
    """``bench SCENE.lod.ply --memory``: an orbit's frames streamed, the figures as JSON; a
    plain scene or another benchmark with it is one line."""
    import json

    path = _lod(tmp_path)
    assert main(["bench", str(path), "--memory", "1.5G", "--quick", "--frames", "2",
                 "--width", "64", "--height", "48", "--json", "-"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["frames"] == 2 and report["chunks_loaded"] >= 1
    assert 0 < report["resident_peak_bytes"] <= 1 << 30 and report["bytes_read"] > 0
    assert main(["bench", str(tmp_path / "s.ply"), "--memory", "4M"]) == 2
    assert "--memory: give one level-of-detail file" in capsys.readouterr().err
    assert main(["bench", str(path), "--memory", "4M", "--lod"]) == 2
    assert "not with --lod" in capsys.readouterr().err


def test_a_read_tree_is_anchored_where_the_file_says(tmp_path):
    """read_lod anchors the nodes at the file's stored anchor (the leaves' box centre), which
    the lazy reader's cut and the streamed frames subtract, not at the box of every node: so an
    in-memory frame of a .lod.ply is its streamed frame (the cut at the same threshold)."""
    path = _lod(tmp_path)
    tree = read_lod(path)
    with LazyLod(path) as lazy:
        assert np.array_equal(tree.nodes.anchor, lazy.anchor)
        assert not np.array_equal(lazy.anchor, tree.nodes.subset(slice(None)).anchor)
