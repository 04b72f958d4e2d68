"""``splatgl bench --scale --lod`` (issue 41 item 6): scenes larger than memory, measured."""

from __future__ import annotations

import json
import tempfile
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from splatgl.measure.bench import scale_lod
from splatgl.measure.bench.scale_lod import (ScaleLodOptions, StepFailed, check_disk, full_fits,
                                    run_scale_lod, run_step)
from splatgl.measure.bench.scale_lod_steps import write_tiled_scene
from splatgl.cli import main
from splatgl.commands._common import demo_scene_path
from splatgl.errors import SplatglError
from splatgl.formats import load_scene

STEPS = ("scene", "build", "open", "frame", "far", "full", "flight", "path")


def _refused(capsys, argv, message):
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert err == message


def test_tiled_scene_is_written_in_blocks(tmp_path):
    """The scene file is written a block at a time: every row there, blocks side by side."""
    demo = load_scene(demo_scene_path())
    path = tmp_path / "s.ply"
    size = write_tiled_scene(path, 2500, block=1000, sources=[demo])
    scene = load_scene(path)
    assert scene.count == 2500 and size == path.stat().st_size
    x = scene.means[:, 0]
    first, second = x[:1000], x[1000:2000]
    assert np.median(second) - np.median(first) > 0.5 * (np.ptp(first))   # the next cell
    assert [p.name for p in tmp_path.iterdir()] == ["s.ply"]   # no temporary left


def test_disk_and_full_detail_limits(tmp_path):
    with pytest.raises(SplatglError, match=r"^--scale --lod: .* free, the scenes of --sizes and "
                                           r"their levels of detail need about .*: choose smaller "
                                           r"--sizes or another TMPDIR$"):
        check_disk(tmp_path, (10**15,), False)
    check_disk(tmp_path, (1000,), True)
    assert full_fits(1000, 10**9) == (True, "")
    fits, why = full_fits(100_000_000, 24 * 2**30)
    assert not fits and why.startswith("does not fit: about ")


def test_a_step_over_the_memory_cap_is_stopped(tmp_path):
    """A step polled past its cap is killed, and a failing step's last line is its message."""
    args = {"lod": str(tmp_path / "none.lod.ply"), "width": 8, "height": 8}
    with pytest.raises(StepFailed, match=r"^stopped at 1 B resident \(the cap: MemAvailable"):
        run_step("open", args, cap=1)
    with pytest.raises(StepFailed, match="none.lod.ply"):
        run_step("open", args)


def _fake_steps(monkeypatch, interrupt_at=None):
    calls = []

    def fake(step, args, cap=0):
        calls.append(step)
        if step == interrupt_at:
            raise KeyboardInterrupt
        if step == "scene":
            Path(args["scene"]).write_bytes(b"x")
        if step in ("frame", "far", "full"):
            np.save(args["image"], np.full((4, 4, 3), 0.51 if step == "full" else 0.5, np.float32))
        if step == "full":
            np.save(args["far_image"], np.full((4, 4, 3), 0.6, np.float32))
        return {"seconds": 1.0, "wall_s": 1.5, "peak_rss_mb": 100.0 * len(calls),
                "fps_median": 12.0, "rest_to_exact_s": 2.0, "frame_ms_median": 80.0}

    monkeypatch.setattr(scale_lod, "run_step", fake)
    return calls


@pytest.mark.slow   # the machine probe's GL context and the plot: about 2 s
def test_cli_writes_json_and_plot_and_removes_scenes(tmp_path, monkeypatch, capsys, shared_scenes):
    calls = _fake_steps(monkeypatch)
    monkeypatch.setattr(scale_lod, "mem_available", lambda: 5 * 10**8)  # 2M does not fit
    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path / "tmp"))
    (tmp_path / "tmp").mkdir()
    out = tmp_path / "out"
    assert main(["bench", "--scale", "--lod", "--sizes", "20k,2M", "--memory", "300M",
                 "--width", "64", "--height", "48", "--out", str(out)]) == 0
    assert calls == list(STEPS) + [s for s in STEPS if s != "full"]
    doc = json.loads((out / "scale-lod.json").read_text())
    assert {"cpu", "simd", "gl_renderer"} <= set(doc["machine"])
    assert doc["options"]["memory"] == 300 << 20 and doc["options"]["width"] == 64
    small, big = doc["rows"]
    assert small["splats"] == 20_000 and set(STEPS) <= set(small)
    assert small["psnr_view_db"] == pytest.approx(-20 * np.log10(0.01), abs=1e-3)
    assert small["psnr_far_db"] == pytest.approx(-20 * np.log10(0.1), abs=1e-3)
    assert big["full"]["skipped"].startswith("does not fit")
    assert big["psnr_far_db"] == big["psnr_view_db"] == big["full"]["skipped"]
    assert (out / "scale-lod.png").stat().st_size > 0
    assert list((tmp_path / "tmp").iterdir()) == []   # the scratch folder is gone
    assert "| 2,000,000 |" in capsys.readouterr().out


def test_interrupt_keeps_what_was_measured(tmp_path, monkeypatch, shared_scenes):
    _fake_steps(monkeypatch, interrupt_at="open")
    scratch = tmp_path / "scratch"
    with pytest.raises(KeyboardInterrupt):
        run_scale_lod(ScaleLodOptions(sizes=(20_000,), scratch=scratch), tmp_path / "out", {})
    row = json.loads((tmp_path / "out" / "scale-lod.json").read_text())["rows"][0]
    assert set(row) == {"splats", "scene", "build"}
    assert list(scratch.iterdir()) == []   # the scene removed (no --keep-scenes)


def test_keep_scenes(tmp_path, monkeypatch, shared_scenes):
    _fake_steps(monkeypatch)
    scratch = tmp_path / "scratch"
    run_scale_lod(ScaleLodOptions(sizes=(20_000,), scratch=scratch, keep_scenes=True), None, {},
                  log=lambda m: None)
    assert (scratch / "scale-20000.ply").is_file()


def test_refusals(tmp_path, capsys, monkeypatch):
    _refused(capsys, ["bench", "--scale", "--lod", "--lod-thresholds", "3"],
             "splatgl: error: --lod-thresholds: not read by --scale --lod (it measures the default "
             "cut of SH0 scenes; the options are --sizes, --width, --height, --memory, --frames, "
             "--keep-scenes, --scratch, --out)")
    _refused(capsys, ["bench", "--scale", "--keep-scenes"],
             "splatgl: error: --keep-scenes: an option of the out-of-core scale benchmark; add "
             "--scale --lod")
    _refused(capsys, ["bench", "--lod", "--memory", "1G"],   # bench --memory streams one SCENE
             "splatgl: error: --memory streams one level of detail in one process; not with --lod")
    _refused(capsys, ["bench", "--scale", "--lod", "--memory", "3X"],
             "splatgl: error: --memory: expected a size such as 200M, 1.5G or 4GiB, got '3X'")
    _refused(capsys, ["bench", "--scale", "--lod", "--json"],
             "splatgl: error: --json: --scale --lod writes its JSON with --out DIR")
    out = tmp_path / "out"
    out.mkdir()
    (out / "scale-lod.json").write_text("keep")
    assert main(["bench", "--scale", "--lod", "--sizes", "20k", "--out", str(out)]) == 2
    assert "--force" in capsys.readouterr().err
    assert (out / "scale-lod.json").read_text() == "keep"
    monkeypatch.setenv("SPLATGL_SHARED_SCENES", str(tmp_path / "none"))
    assert main(["bench", "--scale", "--lod", "--sizes", "20k"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err[-1].startswith("splatgl: error: --scale --lod: ") and "shared real scene not found" in err[-1]


def test_memory_is_the_one_budget_option(monkeypatch, capsys):
    """--scale --lod takes --memory, parsed and defaulted as splatgl lod's (issue 39 item 8: the
    old --lod-memory is gone); the library's default is the same."""
    from splatgl.lod.budget import default_budget
    from splatgl.measure.bench import machine

    seen = []
    monkeypatch.setattr(machine, "probe_machine", lambda: {"cpu": "test"})
    monkeypatch.setattr(machine, "describe", lambda m: "test machine")
    monkeypatch.setattr(scale_lod, "run_scale_lod",
                        lambda options, out, m, log: seen.append(options) or {"rows": []})
    assert main(["bench", "--scale", "--lod", "--sizes", "20k", "--memory", "1.5G"]) == 0
    assert main(["bench", "--scale", "--lod", "--sizes", "20k"]) == 0
    assert [o.memory for o in seen] == [int(1.5 * (1 << 30)), default_budget()[0]]
    assert ScaleLodOptions().memory == default_budget()[0]
    capsys.readouterr()
    assert main(["bench", "--scale", "--lod", "--lod-memory", "2G"]) == 2
    assert "unrecognized arguments: --lod-memory" in capsys.readouterr().err


@pytest.mark.slow
def test_end_to_end_tiny_sizes(tmp_path, shared_scenes):
    """Every step run for real at 20k and 50k splats (a fast flight)."""
    options = ScaleLodOptions(sizes=(20_000, 50_000), memory=1 << 30, width=96, height=64,
                              speed=20.0, block=20_000, path_frames=3)
    report = run_scale_lod(options, tmp_path / "out", {"cpu": "test"}, log=lambda m: None)
    for row in report["rows"]:
        for step in STEPS:
            assert row[step]["peak_rss_mb"] > 0 and row[step]["seconds"] > 0, (step, row[step])
            assert row[step]["wall_s"] >= row[step]["seconds"]
        assert row["build"]["leaves"] == row["splats"]
        for key in ("psnr_view_db", "psnr_far_db"):   # the same views; None: identical
            assert row[key] is None or row[key] > 25, (key, row[key])
        assert row["far"]["cut_nodes"] < row["frame"]["cut_nodes"]   # a cut, not the leaves
        assert row["flight"]["moving_frames"] >= 1 and row["flight"]["reached_exact"]
        assert row["flight"]["rest_to_exact_s"] >= 0 and row["flight"]["samples"]
        path = row["path"]
        assert path["frames"] == len(path["rss_mb"]) == 3 and path["rss_max_mb"] > 0
    assert json.loads((tmp_path / "out" / "scale-lod.json").read_text())["rows"] == report["rows"]


def test_streamed_flight_runs_the_viewers_session_to_exact(tmp_path, gl_renderer, monkeypatch):
    """The flight step over a level of detail streamed under a chunk cache smaller than the
    file: the viewer's own session (its budget's levels while moving), then rest until the
    exact frame with every chunk in; the figures and the per-frame memory samples recorded."""
    from test_stream_session import cache_plan, tiny_lod

    from splatgl.lod.lazy import LazyLod
    from splatgl.lod.selection import LodSettings
    from splatgl.lod.stream import LazyChunks
    from splatgl.lod.stream_view import StreamedScene
    from splatgl.measure.bench.scale_lod_steps import flight

    from splatgl.measure.bench import flight as flight_module

    class Slow(LazyChunks):   # a slow disk, closed until the flight is 0.1 s in (of 0.2 s moving)
        gate = threading.Event()

        def load(self, chunk):
            self.gate.wait(10)
            time.sleep(0.02)
            return super().load(chunk)

    warm_up = flight_module._warm_up

    def then_open(session, flight):   # the chunks arrive while moving and at rest
        warm_up(session, flight)
        threading.Timer(0.1, Slow.gate.set).start()

    monkeypatch.setattr(flight_module, "_warm_up", then_open)
    path = tiny_lod(tmp_path)
    lazy = LazyLod(path)
    chunks = Slow(lazy, 128)
    Slow.gate.set()   # the pinned top levels come first, then the gate closes
    cache = int(0.9 * sum(chunks.estimate(c) for c in range(chunks.count)))
    stream = StreamedScene(path, LodSettings(), 1 << 30, chunks=chunks, plan=cache_plan(cache))
    Slow.gate.clear()
    try:
        r = flight(gl_renderer, stream, {"width": 96, "height": 64, "speed": 40.0})
    finally:
        stream.close()
        lazy.close()
    assert r["moving_frames"] >= 1 and r["fps_median"] > 0 and r["fps_p10"] <= r["fps_median"]
    assert r["target_fps"] == 10.0 and sum(r["levels"].values()) == r["moving_frames"]
    assert r["reached_exact"] and r["rest_to_exact_s"] >= 0.0
    assert 0 < r["resident_max_mb"] * 1e6 <= cache and r["cache_mb"] * 1e6 == cache
    phases = [s["phase"] for s in r["samples"]]
    assert phases[0] == "moving" and phases[-1] == "exact"
    loaded = [s["chunks_loaded"] for s in r["samples"]]
    assert loaded == sorted(loaded) and loaded[-1] == r["chunks_loaded"] > loaded[0]
    assert r["rest_frames"] >= 1 and "rest" in phases   # drawn again as chunks arrived
    assert all(s["rss_mb"] > 0 for s in r["samples"]) and r["rss_max_mb"] >= r["rss_start_mb"]
    assert "refining" not in r["streaming"]


def test_flight_figures_against_the_viewers_targets():
    """The table adds the flight's 10th percentile and one line a size against the targets:
    10 fps moving, exact within 15 s of rest, the flight's peak under --memory."""
    from splatgl.measure.bench.scale_lod_report import table

    rows = [{"splats": 1_000_000, "flight": {"fps_median": 12.04, "fps_p10": 8.46,
                                            "rest_to_exact_s": 3.2, "peak_rss_mb": 900.0}},
            {"splats": 5_000_000, "flight": {"fps_median": 4.0, "fps_p10": 2.0,
                                            "rest_to_exact_s": None, "peak_rss_mb": 2500.0}},
            {"splats": 9, "flight": {"failed": "stopped"}}]
    lines = table(rows, 2 << 30).splitlines()
    assert lines[0].count("|") == 16 and "| moving fps p10 |" in lines[0]
    assert "| 12.0 | 8.5 | 3.20 | 900 |" in lines[2]
    assert lines[-2:] == [
        "flight 1,000,000: moving 12.0 fps median, p10 8.5 (>= 10: met), exact 3.2 s after rest "
        "(<= 15: met), peak 879 MiB of --memory 2048 MiB (met)",
        "flight 5,000,000: moving 4.0 fps median, p10 2.0 (>= 10: NOT met), exact - s after rest "
        "(<= 15: NOT met), peak 2441 MiB of --memory 2048 MiB (NOT met)"]


def test_path_memory_against_flat():
    """A path with its per-frame memory gets one line: flat when its second half's peak is
    within PATH_FLAT of its first half's."""
    from splatgl.measure.bench.scale_lod_report import table

    def path(first, second):
        return {"frames": 60, "frame_s_median": 4.24, "rss_mb": [1000.0], "rss_first_mb": 1000.0,
                "rss_max_first_half_mb": first, "rss_max_second_half_mb": second}

    rows = [{"splats": 20_000_000, "path": path(1400.0, 1420.0)},
            {"splats": 100_000_000, "path": path(1400.0, 1600.0)}]
    assert table(rows).splitlines()[-2:] == [
        "path 20,000,000: 60 frames, 4.2 s a frame, resident 1000 MB after the first, at most "
        "1400 MB in the first half and 1420 MB in the second (flat within 5%: met)",
        "path 100,000,000: 60 frames, 4.2 s a frame, resident 1000 MB after the first, at most "
        "1400 MB in the first half and 1600 MB in the second (flat within 5%: NOT met)"]
