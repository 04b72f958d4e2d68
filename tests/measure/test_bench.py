"""`splatgl bench`: rows, outputs, the limit row, fragment counts and the Pareto front."""

from __future__ import annotations

import csv
import json
import math

import numpy as np
import pytest

from splatgl.measure.bench.probes import count_fragments
from helpers import view_for
from splatgl.measure.bench.configs import RowKind, configurations
from splatgl.measure.bench.report import pareto_front
from splatgl.measure.bench.runner import BenchOptions, bench_scene
from splatgl.cli import main
from splatgl.imagefiles.images import read_image
from splatgl.api import default_camera
from splatgl.scene.splats import Scene
from splatgl.scene.settings import QuadExtent, RenderSettings


def test_pareto_front():
    pts = [(1.0, 5.0), (2.0, 1.0), (3.0, 3.0), (0.5, 9.0), (2.0, 2.0)]
    assert pareto_front(pts) == [3, 0, 1]


def test_configurations_cover_every_question():
    rows = configurations(RenderSettings(), scene_sh_degree=3, cpu=True)
    groups = {r.group for r in rows}
    assert groups == {"default", "precision", "extent", "sort", "sh", "storage", "resort", "preprocess", "cull",
                      "early-stop", "projection", "renderer", "limit"}
    assert [r.name for r in rows if r.group == "early-stop"] == ["early-stop=on", "early-stop=off"]
    assert {r.name for r in rows if r.group == "sh"} == {"sh<=0", "sh<=1", "sh<=2"}
    assert [r.name for r in rows if r.group == "storage"] == ["storage=half-sh", "storage=compact"]
    assert [r.kind for r in rows if r.group == "renderer"] == [RowKind.TILE, RowKind.CPU,
                                                               RowKind.REFERENCE]
    no_cpu = configurations(RenderSettings(), 3, cpu=False)
    assert [r.kind for r in no_cpu if r.group == "renderer"] == [RowKind.TILE, RowKind.REFERENCE]
    quick = configurations(RenderSettings(), 0, quick=True)
    assert len(quick) < len(rows) and {r.group for r in quick} >= {"default", "limit", "extent"}


def test_ellipse_fragment_efficiency_is_pi_over_4(gl_renderer):
    """Inside an axis-aligned rectangle, the inscribed ellipse covers pi/4 of the pixels."""
    rng = np.random.default_rng(6)
    n = 400
    scene = Scene(rng.normal(size=(n, 3)), rng.normal(size=(n, 4)), rng.normal(-2.0, 0.3, (n, 3)),
                  rng.normal(2.0, 0.5, n), rng.normal(0, 0.2, (n, 1, 3)))
    cam = default_camera(scene, 320, 240)
    quad = gl_renderer.renderer_for(scene, RenderSettings())
    shaded, kept = count_fragments(quad, view_for(quad, cam))
    assert shaded > 100_000
    assert kept / shaded == pytest.approx(math.pi / 4, abs=0.01)
    square = gl_renderer.renderer_for(scene, RenderSettings(extent=QuadExtent.SQUARE))
    s2, k2 = count_fragments(square, view_for(square, cam))
    assert k2 / s2 < kept / shaded and abs(k2 - kept) / kept < 0.02  # same kept, more shaded


@pytest.mark.slow
def test_bench_scene_rows_and_limit(gl_renderer):
    rng = np.random.default_rng(1)
    n = 300
    scene = Scene(rng.normal(size=(n, 3)), rng.normal(size=(n, 4)), rng.normal(-2.5, 0.3, (n, 3)),
                  rng.normal(1.0, 1.0, n), rng.normal(0, 0.2, (n, 4, 3)))
    rows = bench_scene(gl_renderer, "syn", scene, BenchOptions(64, 48, 3, error_frames=(2,), quick=True))
    by = {r.config: r for r in rows}
    assert by["limit"].limit_ratio == pytest.approx(1.0)
    assert by["default"].psnr > 60 and by["reference"].psnr == math.inf
    assert by["tile"].psnr > 100
    assert by["default"].drawn <= n and by["default"].fragment_efficiency > 0.5
    assert all(r.frame_ms > 0 and r.frame_ms_p10 <= r.frame_ms <= r.frame_ms_p90 for r in rows)
    assert by["sh<=0"].psnr < by["default"].psnr  # dropping SH bands costs accuracy
    on = by["early-stop=on"]  # rasterised counted only where early termination is on
    assert by["default"].fragments_rasterised is None
    # The default (auto) leaves this sparse scene's views unbatched; on batches every view.
    assert by["default"].batched_share == 0.0 and on.batched_share == 1.0
    # Auto's estimate of a plain draw's fragments (area against pixel-centre counts of 300
    # small quads: within 10%); on makes the same one (for its schedule).
    assert by["default"].fragments_estimate == pytest.approx(by["default"].fragments_shaded, rel=0.1)
    assert on.fragments_estimate == by["default"].fragments_estimate
    assert on.fragments_shaded <= on.fragments_rasterised <= by["default"].fragments_shaded
    # Each quad row carries the frame's transfers (issue 40 item 3): the image read back at
    # least, and the sorted indices uploaded (the CPU order).
    moved = by["default"].transfers
    assert set(moved) == {"upload_bytes", "readback_bytes", "syncs"}
    assert moved["readback_bytes"] >= 64 * 48 * 16 and moved["upload_bytes"] >= 4 * by["default"].drawn
    assert by["tile"].transfers is None or "syncs" in by["tile"].transfers


def test_early_stop_table_reads_modes_and_auto_decision():
    from splatgl.measure.bench.early_stop_report import early_stop_table
    from splatgl.measure.bench.runner import BenchRow

    def row(config, group, ms, **kw):
        return BenchRow("s.ply", 1000, config, group, "quad", ms, ms, ms, **kw)

    rows = [row("default", "default", 80.0, batched_share=1.0, fragments_estimate=400_000,
                drawn=1000),
            row("early-stop=on", "early-stop", 75.0, fragments_shaded=100, reference_fragments=50),
            row("early-stop=off", "early-stop", 100.0, fragments_shaded=300)]
    head, line = early_stop_table(rows, pixels=20_000).splitlines()
    assert "frag/quad" in head and "frag/px" in head
    # off 100, on 75 (1.33x), auto 80 (1.25x), all batched, 400 per quad, 20 per pixel, on/ref 2
    assert line.split()[1:12] == ["1000", "100.0", "75.0", "1.33x", "80.0", "1.25x", "100%", "400",
                                  "20.0", "300", "100"]
    assert early_stop_table(rows[:1]) == ""


def test_storage_rows_report_bytes_and_psnr_against_float32(gl_renderer):
    from splatgl.measure.bench.storage_report import storage_table

    rng = np.random.default_rng(2)
    n = 300
    scene = Scene(rng.normal(size=(n, 3)), rng.normal(size=(n, 4)), rng.normal(-2.5, 0.3, (n, 3)),
                  rng.normal(1.0, 1.0, n), rng.normal(0, 0.2, (n, 4, 3)))
    rows = bench_scene(gl_renderer, "syn", scene,
                       BenchOptions(64, 48, 2, error_frames=(1,), groups=frozenset({"storage"})))
    by = {r.config: r for r in rows}
    # SH degree 1: 9 rest values per splat, float32 / float16 (splatgl/gl/storage.py).
    assert [by[c].gpu_bytes_per_splat for c in ("default", "storage=half-sh", "storage=compact")] \
        == [64 + 36, 64 + 18, 32 + 18]
    assert by["default"].psnr_float32 is None
    assert 60 < by["storage=compact"].psnr_float32 < by["storage=half-sh"].psnr_float32
    assert by["storage=compact"].psnr > 50  # against the reference
    lines = storage_table(rows).splitlines()
    assert len(lines) == 4 and lines[3].split()[1:4] == ["storage=compact", "50.0", "2.00"]


@pytest.mark.slow
def test_bench_quick_cli_writes_table_csv_json_plot(tmp_path, capsys):
    assert main(["bench", "--quick", "--frames", "2", "--out", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert "limit" in out and "target check demo" in out and "exact sort" in out
    data = json.loads((tmp_path / "bench.json").read_text())
    assert {r["config"] for r in data["rows"]} >= {"default", "tile", "reference", "limit"}
    # The machine line names the GL renderer (which device ran the rows), in the JSON too.
    renderer = data["machine"]["gl_renderer"]
    assert renderer not in ("", "?") and data["renderer"] == renderer
    assert f"GL renderer {renderer}, cull" in out
    with open(tmp_path / "bench.csv") as fh:
        assert len(list(csv.DictReader(fh))) == len(data["rows"])
    png = read_image(tmp_path / "bench.png")
    assert png.shape[0] > 200 and png.std() > 0.01


def test_savings_rows_show_each_saving(gl_renderer):
    from splatgl.measure.bench.savings import savings_rows

    rng = np.random.default_rng(3)
    n = 3000
    scene = Scene(rng.normal(size=(n, 3)), rng.normal(size=(n, 4)), rng.normal(-3.0, 0.3, (n, 3)),
                  rng.normal(1.0, 1.0, n), rng.normal(0, 0.2, (n, 1, 3)))
    rows = savings_rows(gl_renderer, "syn", scene, BenchOptions(64, 48, 3))
    by = {r.config: r for r in rows}
    assert {"sh0 as stored (compute)", "padded to sh3 (compute)", "sh0 as stored (vertex)",
            "padded to sh3 (vertex)"} <= set(by)
    off = [r for r in rows if r.config.endswith("off-screen, culled")][0]
    not_culled = [r for r in rows if r.config.endswith("off-screen, not culled")][0]
    assert off.drawn < 0.25 * n and off.drawn < 0.5 * not_culled.drawn  # culling removed most
    assert by["still camera"].frame_ms > 0 and by["moving camera (orbit)"].frame_ms > 0


def test_benchmark_modes_are_one_table(capsys):
    """The benchmarks bench runs instead of the scene benchmark are declared once
    (_bench_modes.MODES): each a flag, and every refusal of two at once names them in its order."""
    from splatgl.commands._bench_modes import MODES

    assert list(MODES) == ["interactive", "scale", "lod", "popping"]
    assert main(["bench", "--lod", "--interactive"]) == 2
    assert capsys.readouterr().err.strip() == (
        "splatgl: error: --interactive and --lod are separate benchmarks: run one at a time "
        "(each writes its own JSON with --out DIR)")
    assert main(["bench", "--popping", "--scale"]) == 2
    assert "--popping runs alone in one process" in capsys.readouterr().err
    assert main(["bench", "x.lod.ply", "--memory", "1G", "--popping", "--scale"]) == 2
    assert capsys.readouterr().err.strip() == (
        "splatgl: error: --memory streams one level of detail in one process; not with --scale, "
        "--popping")


def test_a_row_without_an_error_figure_shows_a_dash_not_a_dash_percent():
    """bench --quick's fisheye row printed '-%' in the >1/255 column."""
    from splatgl.measure.bench.report import table
    from splatgl.measure.bench.runner import BenchRow

    rows = [BenchRow("s", 10, "a", "g", "quad", 1.0, 1.0, 1.0, off_1=0.25),
            BenchRow("s", 10, "b", "g", "quad", 1.0, 1.0, 1.0)]
    lines = table(rows).splitlines()
    assert lines[-2].endswith(" 25.000%") and lines[-1].endswith(" -") and "-%" not in lines[-1]
    assert len(lines[-1]) == len(lines[-2]) == len(lines[-3])
