"""``splatgl bench --scale --lod --scratch DIR``: a size's scene and level of detail kept in DIR
are used again by the next run (no scene or build step), their build figures from build-N.json;
a stale file is refused in one line; the option belongs to --scale --lod."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from splatgl.cli import main
from splatgl.commands._common import demo_scene_path
from splatgl.errors import SplatglError
from splatgl.formats import load_scene
from splatgl.measure.bench import machine, scale_lod
from splatgl.measure.bench.scale_lod import ROW_BYTES, ScaleLodOptions, disk_need, run_scale_lod
from splatgl.measure.bench.scale_lod_report import table
from splatgl.measure.bench.scale_lod_reuse import Found, find
from splatgl.measure.bench.scale_lod_steps import step_build, write_tiled_scene

N = 3000
FIGURES = {"seconds": 1.0, "wall_s": 1.5, "peak_rss_mb": 100.0}


@pytest.fixture
def steps(monkeypatch):
    """Steps run in this process: the scene and level of detail written for real (the demo
    scene tiled), the others faked; the steps run are listed."""
    demo = load_scene(demo_scene_path())
    calls = []

    def fake(step, args, cap=0):
        calls.append(step)
        extra = {}
        if step == "scene":
            write_tiled_scene(Path(args["scene"]), args["splats"], block=args["splats"], sources=[demo])
        elif step == "build":
            extra = step_build(args)
        elif step in ("frame", "far"):
            np.save(args["image"], np.zeros((4, 4, 3), np.float32))
        return {**extra, **FIGURES}

    monkeypatch.setattr(scale_lod, "run_step", fake)
    monkeypatch.setattr(scale_lod, "REAL_SOURCES", ())   # the demo scene stands in
    return calls


def _run(scratch: Path, n: int = N) -> dict:
    options = ScaleLodOptions(sizes=(n,), memory=1 << 30, scratch=scratch, keep_scenes=True,
                              available=0)   # no full-detail step
    return run_scale_lod(options, None, {}, log=lambda m: None)["rows"][0]


def test_a_second_run_reuses_the_scene_and_its_build(tmp_path, steps):
    scratch = tmp_path / "scratch"
    first = _run(scratch)
    assert steps == ["scene", "build", "open", "frame", "far", "flight", "path"]
    scene, lod = scratch / f"scale-{N}.ply", scratch / f"scale-{N}.lod.ply"
    record = json.loads((scratch / f"build-{N}.json").read_text())
    assert record == {"scene": first["scene"], "build": first["build"]}
    assert record["build"]["leaves"] == N
    mtimes = [p.stat().st_mtime_ns for p in (scene, lod)]
    steps.clear()
    row = _run(scratch)
    assert steps == ["open", "frame", "far", "flight", "path"]   # no scene, no build
    assert [p.stat().st_mtime_ns for p in (scene, lod)] == mtimes
    assert row["scene"] == {**first["scene"], "reused": True, "file": str(scene)}
    assert row["build"] == {**first["build"], "reused": True, "file": str(lod)}
    assert "| 3,000 | 1.0 (reused) | 100 (reused) | 1.00 |" in table([row])
    (scratch / f"build-{N}.json").unlink()   # no figures of the earlier run: the path alone
    row = _run(scratch)
    assert row["scene"] == {"reused": str(scene)} and row["build"] == {"reused": str(lod)}
    assert "| 3,000 | reused | reused | 1.00 |" in table([row])


def test_a_scene_without_its_level_of_detail_is_reused_and_built(tmp_path, steps):
    scratch = tmp_path / "scratch"
    _run(scratch)
    (scratch / f"scale-{N}.lod.ply").unlink()
    steps.clear()
    row = _run(scratch)
    assert steps == ["build", "open", "frame", "far", "flight", "path"]
    assert row["scene"]["reused"] is True and "reused" not in row["build"]
    assert (scratch / f"scale-{N}.lod.ply").is_file()


def test_without_keep_only_what_the_run_made_is_removed(tmp_path, steps):
    scratch = tmp_path / "scratch"
    _run(scratch)
    (scratch / f"scale-{N}.lod.ply").unlink()
    run_scale_lod(ScaleLodOptions(sizes=(N,), memory=1 << 30, scratch=scratch, available=0),
                  None, {}, log=lambda m: None)
    assert sorted(p.name for p in scratch.iterdir()) == [f"scale-{N}.ply"]


def test_a_stale_file_is_refused_in_one_line(tmp_path, steps, monkeypatch, capsys):
    demo = load_scene(demo_scene_path())
    scratch = tmp_path / "scratch"
    scratch.mkdir()
    scene = scratch / f"scale-{N}.ply"
    write_tiled_scene(scene, N - 1, block=N, sources=[demo])
    with pytest.raises(SplatglError) as err:
        _run(scratch)
    assert str(err.value) == (f"--scale --lod: {scene}: stale (its header says {N - 1} splats, the "
                              f"size is {N}); delete it to build it again")
    data = scene.read_bytes()
    scene.write_bytes(data[:-ROW_BYTES])
    with pytest.raises(SplatglError) as err:
        _run(scratch)
    assert str(err.value) == (f"--scale --lod: {scene}: stale (the file is cut short "
                              f"({len(data) - ROW_BYTES} of {len(data)} bytes)); delete it to build "
                              "it again")
    scene.unlink()
    lod = scratch / f"scale-{N}.lod.ply"
    lod.write_bytes(b"x")
    with pytest.raises(SplatglError, match=r"^--scale --lod: .*scale-3000.lod.ply: stale \(its "
                                           r"scene scale-3000.ply is not there to build it again\)"):
        _run(scratch)
    _run(tmp_path / "other")
    (tmp_path / "other" / f"scale-{N}.ply").replace(scene)
    with pytest.raises(SplatglError, match=r"^--scale --lod: .*scale-3000.lod.ply: stale \(not a "
                                           r"PLY file .*\); delete it to build it again$"):
        _run(scratch)
    (tmp_path / "other" / f"scale-{N}.lod.ply").replace(lod)
    with pytest.raises(SplatglError, match=r"^--scale --lod: .*scale-3000.lod.ply: stale \(branching "
                                           r"4, the run's is 8\); delete it to build it again$"):
        find(scratch, N, 8)
    assert find(scratch, N, 4) == Found(True, True)
    lod.write_bytes(b"")
    assert steps == ["scene", "build", "open", "frame", "far", "flight", "path"]   # the other folder's
    # the CLI: one line, before anything is measured
    monkeypatch.setattr(machine, "probe_machine", lambda: {"cpu": "test"})
    monkeypatch.setattr(machine, "describe", lambda m: "test machine")
    capsys.readouterr()
    assert main(["bench", "--scale", "--lod", "--sizes", "3k", "--scratch", str(scratch)]) == 2
    assert capsys.readouterr().err.strip() == (f"splatgl: error: --scale --lod: {lod}: stale (the "
                                               "file is empty); delete it to build it again")
    assert steps == ["scene", "build", "open", "frame", "far", "flight", "path"]


def test_scratch_is_kept_and_read_by_scale_lod_only(tmp_path, monkeypatch, capsys):
    seen = []
    monkeypatch.setattr(machine, "probe_machine", lambda: {"cpu": "test"})
    monkeypatch.setattr(machine, "describe", lambda m: "test machine")
    monkeypatch.setattr(scale_lod, "run_scale_lod",
                        lambda options, out, m, log: seen.append(options) or {"rows": []})
    assert main(["bench", "--scale", "--lod", "--sizes", "20k", "--scratch", str(tmp_path)]) == 0
    assert seen[0].scratch == tmp_path and seen[0].keep_scenes
    for argv in (["--scale"], ["--lod"], []):
        assert main(["bench", *argv, "--scratch", str(tmp_path)]) == 2
        assert capsys.readouterr().err.strip() == ("splatgl: error: --scratch: an option of the "
                                                   "out-of-core scale benchmark; add --scale --lod")


def test_disk_counts_only_the_missing_files():
    n, scene = 10**6, 10**6 * ROW_BYTES
    assert disk_need((n,), True) == pytest.approx(scene * 2.4 + scene * 1.2, abs=1)
    assert disk_need((n,), False) == pytest.approx(scene * 3.6, abs=1)
    assert disk_need((n,), True, {n: Found(True, True)}) == 0
    assert disk_need((n,), False, {n: Found(True, False)}) == pytest.approx(scene * 2.6, abs=1)
    assert disk_need((n, 2 * n), True, {2 * n: Found(True, True)}) == pytest.approx(scene * 3.6, abs=1)
