"""``splatgl edit`` and ``splatgl info --stats`` (issue 30): the command line gives what the
Python API gives, refuses in one line before reading, writes atomically, --dry-run writes
nothing; the real scenes go through every operation."""

from __future__ import annotations

import json

import numpy as np
import pytest

from helpers import random_scene, shared_file
from splatgl.cli import main
from splatgl.edit import (CropSphere, Decimate, Filter, RemoveFloaters, ShDegree, edit_files,
                          merge_scenes)
from splatgl.edit.statistics import attribute_statistics, overdraw
from splatgl.formats import load_scene, save_scene
from splatgl.scene.splats import Scene
from splatgl.scene.transform import SceneTransform


def cli(capsys, *argv):
    code = main(["edit", *map(str, argv)])
    out, err = capsys.readouterr()
    return code, out, err


def one_line_error(capsys, *argv) -> str:
    code, out, err = cli(capsys, *argv)
    assert code == 2 and err.startswith("splatgl: error: ") and err.count("\n") == 1, err
    return err[len("splatgl: error: "):-1]


@pytest.fixture
def scene_file(tmp_path):
    path = tmp_path / "in.ply"
    save_scene(path, random_scene(3000, seed=11, degree=2, spread=1.0))
    return path


def test_cli_and_api_write_the_same_file(tmp_path, capsys, scene_file):
    code, out, _ = cli(capsys, scene_file, "-o", tmp_path / "cli.ply", "--crop-sphere", "0,0,0,1.5",
                       "--remove", "opacity < 0.3", "--remove-floaters", "neighbours=8",
                       "--decimate", "40%", "--sh-degree", "1")
    assert code == 0
    report = edit_files([scene_file], tmp_path / "api.ply",
                        [CropSphere((0, 0, 0), 1.5), Filter("opacity < 0.3", invert=True),
                         RemoveFloaters(neighbours=8), Decimate(percent=40), ShDegree(1)])
    assert (tmp_path / "cli.ply").read_bytes() == (tmp_path / "api.ply").read_bytes()
    lines = [line.split()[0] for line in out.splitlines()[1:-1]]
    assert lines == ["crop-sphere", "filter", "remove-floaters", "decimate", "sh-degree"]
    for step in report.steps:
        assert f"{step.removed:,}" in out
    assert report.count == load_scene(tmp_path / "cli.ply").count
    assert f"wrote  {tmp_path / 'cli.ply'}" in out and "SH degree 1" in out


def test_dry_run_prints_the_removals_and_writes_nothing(tmp_path, capsys, scene_file):
    out_path = tmp_path / "out.ply"
    code, out, _ = cli(capsys, scene_file, "-o", out_path, "--filter", "opacity >= 0.5",
                       "--dry-run")
    assert code == 0 and not out_path.exists() and list(tmp_path.iterdir()) == [scene_file]
    kept = int((load_scene(scene_file).opacities >= 0.5).sum())
    assert f"-> {kept:,}" in out and f"dry run: would write {kept:,} splats" in out
    code, out, _ = cli(capsys, scene_file, "--remove-floaters", "--dry-run", "--json")
    report = json.loads(out)
    assert code == 0 and report["dry_run"] and report["output"] is None
    assert report["steps"][0]["operation"] == "remove-floaters"
    assert "threshold" in report["steps"][0]["detail"]


@pytest.mark.parametrize("argv,message", [
    (["--crop-box", "1,0,0,0,1,1"], "--crop-box: min x 1 > max x 0: the box is empty"),
    (["--filter", "import os"], "--filter 'import os': syntax error"),
    (["--invert"], "--invert must follow a --crop-box, --crop-sphere, --filter or --remove"),
    (["--decimate", "10", "--invert"], "--invert applies to --crop-box, --crop-sphere, "
                                       "--filter and --remove, not --decimate"),
    (["--transform", "{}", "--transform", "{}", "--sh-degree", "1"],
     "--transform given 2 time(s) for 1 input(s)"),
    (["--crop-sphere", "0,0,0,100", "-o", "x.xyz"], "cannot write this format"),
    (["--sh-degree", "0", "--spz-axes", "rdf"], "--spz-axes applies to .spz inputs only"),
])
def test_bad_options_are_one_line_before_reading(tmp_path, capsys, argv, message, monkeypatch,
                                                 scene_file):
    import splatgl.edit.files as files

    monkeypatch.setattr(files, "load_scene", lambda *a, **k: pytest.fail("read before refusing"))
    argv = [a if a != "x.xyz" else tmp_path / a for a in argv]
    if "-o" not in argv:
        argv += ["-o", tmp_path / "out.ply"]
    assert message in one_line_error(capsys, scene_file, *argv)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["in.ply"]


def test_existing_output_needs_force_and_failures_leave_nothing(tmp_path, capsys, scene_file):
    out_path = tmp_path / "out.ply"
    out_path.write_bytes(b"old")
    line = one_line_error(capsys, scene_file, "-o", out_path, "--sh-degree", "0")
    assert "exists (use --force to replace it)" in line and out_path.read_bytes() == b"old"
    line = one_line_error(capsys, scene_file, "-o", out_path, "--crop-sphere", "50,50,50,1",
                          "--force")
    assert line.startswith("edit: no splats left (crop-sphere [inside sphere centre 50,50,50 "
                           "radius 1] removed the last 3,000)")
    assert out_path.read_bytes() == b"old"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["in.ply", "out.ply"]  # no temporary


def test_allow_empty_writes_a_scene_of_no_splats(tmp_path, capsys, scene_file):
    out_path = tmp_path / "empty.ply"
    code, out, _ = cli(capsys, scene_file, "-o", out_path, "--crop-box", "5,5,5,6,6,6",
                       "--allow-empty")
    assert code == 0 and "0 splats" in out
    assert b"element vertex 0\n" in out_path.read_bytes()
    for ext in ("sog", "compressed.ply", "glb", "splat"):
        line = one_line_error(capsys, scene_file, "-o", tmp_path / f"e.{ext}", "--crop-box",
                              "5,5,5,6,6,6", "--allow-empty")
        assert line.endswith("format cannot hold zero splats; nothing written (write .ply or "
                             ".spz for an empty scene)")
        assert not (tmp_path / f"e.{ext}").exists()


def test_merge_with_transforms_through_the_cli(tmp_path, capsys):
    a, b = random_scene(40, seed=1, degree=0), random_scene(60, seed=2, degree=1)
    save_scene(tmp_path / "a.ply", a)
    save_scene(tmp_path / "b.ply", b)
    move = '{"translate": [2, 0, 0], "rotate_deg": [0, 0, 90]}'
    code, out, _ = cli(capsys, tmp_path / "a.ply", tmp_path / "b.ply", "-o", tmp_path / "m.ply",
                       "--transform", "{}", "--transform", move)
    assert code == 0 and "merged 100 splats from 2 inputs" in out
    got = load_scene(tmp_path / "m.ply")
    expected = merge_scenes([a, b], [None, SceneTransform.from_euler((0, 0, 90), (2, 0, 0))])
    assert got.sh_degree == 1 and np.array_equal(got.means, expected.means)
    assert np.array_equal(got.sh, expected.sh)


def test_drop_invalid_is_counted_as_the_first_step(tmp_path, capsys):
    s = random_scene(10)
    means = np.array(s.means)
    means[[2, 5]] = np.nan
    save_scene(tmp_path / "bad.ply", Scene(means, s.quats, s.log_scales, s.opacity_logits, s.sh))
    code, out, err = cli(capsys, tmp_path / "bad.ply", "-o", tmp_path / "ok.ply", "--drop-invalid")
    step = next(line for line in out.splitlines() if "drop-invalid" in line).split()
    assert code == 0 and step[:4] == ["drop-invalid", "removed", "2", "(20.00%)"]
    assert step[4:6] == ["->", "8"]
    assert "warning" not in err
    assert load_scene(tmp_path / "ok.ply").count == 8


def test_no_operation_is_refused(tmp_path, capsys, scene_file):
    line = one_line_error(capsys, scene_file, "-o", tmp_path / "y.ply")
    assert line.startswith("edit: no operation given") and "splatgl convert" in line


# ------------------------------------------------------------------ info --stats


def test_info_stats_prints_what_filters_see(tmp_path, capsys, scene_file):
    assert main(["info", str(scene_file), "--stats", "--json", str(tmp_path / "i.json")]) == 0
    out = capsys.readouterr().out
    s = load_scene(scene_file)
    stats = json.loads((tmp_path / "i.json").read_text())
    assert stats["attributes"]["opacity"]["median"] == pytest.approx(float(np.median(s.opacities)))
    assert stats["attributes"]["max_scale"]["max"] == pytest.approx(float(s.scales.max()), rel=1e-6)
    assert stats["attributes"] == json.loads(json.dumps(attribute_statistics(s)))
    assert "anisotropy" in out and "fragments per pixel in the default 1280x720 view" in out
    assert stats["overdraw"]["per_pixel"] == pytest.approx(overdraw(s)["per_pixel"])


def test_info_stats_of_surfels_has_two_scales(tmp_path, capsys):
    from helpers import SURFELS

    save_scene(tmp_path / "s.ply", random_scene(300, **SURFELS))
    assert main(["info", str(tmp_path / "s.ply"), "--stats", "--json"]) == 0
    stats = json.loads(capsys.readouterr().out)
    assert "scale_1" in stats["attributes"] and "scale_2" not in stats["attributes"]
    assert stats["overdraw"]["per_pixel"] > 0


def test_overdraw_is_the_quad_paths_own_coverage_estimate(ctx):
    """info --stats's fragments equal what --early-stop auto's coverage pass estimates on the
    GPU for the same default view (float32 sums on the GPU: 1e-3 relative)."""
    from helpers import draw
    from splatgl.api import default_camera
    from splatgl.scene.settings import RenderSettings
    from splatgl.renderers.quad import QuadRenderer

    scene = random_scene(4000, seed=9, spread=1.0, log_scale=(-3.5, 0.5))
    cam = default_camera(scene, 160, 90)
    r = QuadRenderer(ctx, scene, RenderSettings(early_stop="on"))
    draw(r, cam)
    ours = overdraw(scene, cam)
    assert ours["fragments"] == pytest.approx(r.batches.fragments_estimate, rel=1e-3)
    assert ours["per_pixel"] == pytest.approx(ours["fragments"] / (160 * 90))
    r.release()


# ------------------------------------------------------------------ the real scenes


@pytest.mark.shared
@pytest.mark.slow
@pytest.mark.parametrize("name", ["ply/donut_sh0.ply", "compressed_ply/guitar.compressed.ply",
                                  "spz/biker_v4.spz"])
def test_every_operation_on_the_real_scenes(tmp_path, capsys, shared_scenes, name):
    path = shared_file(shared_scenes, name)
    s = load_scene(path)
    lo, hi = s.robust_bounds
    centre = ",".join(f"{v:.6g}" for v in (lo + hi) / 2)
    radius = 0.4 * float(np.linalg.norm(hi - lo))
    out_path = tmp_path / "out.spz"
    code, out, err = cli(capsys, path, "-o", out_path, "--crop-sphere", f"{centre},{radius:.6g}",
                         "--remove", "opacity < 0.02 or anisotropy > 100", "--remove-floaters",
                         "--decimate", "50%", "--sh-degree", "0")
    assert code == 0, err
    counts = [int(line.split("->")[1].split()[0].replace(",", ""))
              for line in out.splitlines() if "->" in line]
    assert counts == sorted(counts, reverse=True) and 0 < counts[-1] < s.count
    assert load_scene(out_path).count == counts[-1]


# ------------------------------------------------------------------ Ctrl-C


@pytest.mark.slow
def test_ctrl_c_during_an_operation_is_one_line_and_leaves_no_file(tmp_path, scene_file):
    """SIGINT while floaters are sought (the operation waits until the signal arrives): exit
    130, one line, no output and no temporary."""
    import signal
    import subprocess
    import sys
    import textwrap

    from helpers import signal_and_wait

    code = textwrap.dedent("""
        import sys, threading
        from splatgl.edit import floaters
        def stuck(self, means, opacity, progress=None):
            print("seeking", flush=True)
            threading.Event().wait()    # until SIGINT raises here
        floaters.RemoveFloaters.find = stuck
        from splatgl.cli import main
        sys.exit(main(["edit", sys.argv[1], "-o", sys.argv[2], "--remove-floaters"]))
        """)
    proc = subprocess.Popen([sys.executable, "-c", code, str(scene_file), str(tmp_path / "o.ply")],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            start_new_session=True)
    assert proc.stdout.readline() == "seeking\n"
    rest, err = signal_and_wait(proc, signal.SIGINT)
    assert (proc.returncode, rest, err) == (130, "", "splatgl: interrupted\n")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["in.ply"]


# ------------------------------------------------------------------ issue 38


@pytest.mark.parametrize("move", ['{"translate": [1e39, 0, 0]}', '{"scale": 1e300}'])
def test_a_transform_to_infinite_positions_is_one_line_and_writes_nothing(tmp_path, capsys,
                                                                          scene_file, move):
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("error")   # no raw NumPy warning may reach the user
        line = one_line_error(capsys, scene_file, "-o", tmp_path / "o.ply", "--transform", move)
    assert line.startswith(f"--transform of {scene_file} (")
    assert line.endswith("beyond float32's range (|coordinate| <= 3.4e38): its position would "
                         "be infinite")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["in.ply"]


def test_a_transform_alone_is_the_operation(tmp_path, capsys, scene_file):
    code, out, _ = cli(capsys, scene_file, "-o", tmp_path / "t.ply", "--transform",
                       '{"translate": [1, 2, 3]}')
    assert code == 0 and f"transform        placed       3,000              [{scene_file}: " \
        "translate 1,2,3]" in out
    moved, before = load_scene(tmp_path / "t.ply"), load_scene(scene_file)
    assert np.array_equal(moved.means, (before.means.astype(np.float64) + [1, 2, 3])
                          .astype(np.float32))
    line = one_line_error(capsys, scene_file, "-o", tmp_path / "u.ply", "--transform", "{}")
    assert line.startswith("edit: no operation given")


@pytest.mark.parametrize("n", [3, 7, 9])
def test_decimate_to_one_splat_on_small_scenes(tmp_path, capsys, n):
    save_scene(tmp_path / "s.ply", random_scene(n, seed=n))
    code, out, err = cli(capsys, tmp_path / "s.ply", "-o", tmp_path / "o.ply", "--decimate", "1")
    assert (code, err) == (0, "") and "[to 1 splat by moment matching" in out
    assert ": 1 splat, SH degree 0" in out and load_scene(tmp_path / "o.ply").count == 1
    code, out, err = cli(capsys, tmp_path / "s.ply", "--decimate", "0.01%", "--dry-run")
    assert (code, err) == (0, "") and "dry run: would write 1 splat," in out


def test_notes_instead_of_silent_or_infinite_figures(tmp_path, capsys, scene_file):
    code, out, err = cli(capsys, scene_file, "--decimate", "5000", "--dry-run")
    assert code == 0 and "the scene has 3,000 splats, not more than 5,000: nothing merged" in out
    save_scene(tmp_path / "tiny.ply", random_scene(4))
    code, out, err = cli(capsys, tmp_path / "tiny.ply", "--remove-floaters", "--dry-run")
    assert code == 0 and "inf" not in out
    assert "4 splats, not more than the 16 neighbours: none can be isolated, none removed" in out


def test_crops_at_the_limits_of_the_numbers(tmp_path, capsys, scene_file):
    code, out, err = cli(capsys, scene_file, "--crop-sphere", "0,0,0,1e308", "--dry-run")
    assert (code, err) == (0, "") and "would write 3,000 splats" in out
    code, out, err = cli(capsys, scene_file, "--crop-box", "-inf,-inf,-inf,inf,inf,0",
                         "--dry-run")   # a value starting with '-' needs no '='
    below = int((load_scene(scene_file).means[:, 2] <= 0).sum())
    assert (code, err) == (0, "") and f"dry run: would write {below:,} splats" in out


@pytest.mark.parametrize("argv,message", [
    (["--crop-sphere", "0,0,0,1", "--invert", "--invert"],
     "--invert given twice after --crop-sphere (the second would undo the first): give it once"),
    (["--transform", '{"scale": 2, "scale": 3}'],
     "--transform: key 'scale' given twice in one object (JSON keeps only the last)"),
    (["--crop-box", '{"min": [0, 0, 0], "max": [1, 1, 1], "rotate": [0, 0, 1]}'],
     "--crop-box: unknown key(s) ['rotate']"),
    (["--remove", "opacity <"], "--remove 'opacity <': syntax error at column 10 (the "
                                "expression ends too early)"),
    (["--remove", "opacity < 0.1", "--decimate", "2", "--invert"],
     "--invert applies to --crop-box, --crop-sphere, --filter and --remove, not --decimate"),
])
def test_issue38_refusals_are_one_line(tmp_path, capsys, scene_file, argv, message):
    line = one_line_error(capsys, scene_file, "-o", tmp_path / "o.ply", *argv)
    assert line.startswith(message)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["in.ply"]


def test_a_transform_file_with_a_repeated_key_is_refused(tmp_path, capsys, scene_file):
    t = tmp_path / "t.json"
    t.write_text('{"translate": [1, 0, 0], "translate": [0, 0, 0]}')
    line = one_line_error(capsys, scene_file, "-o", tmp_path / "o.ply", "--transform", t)
    assert line.startswith("--transform: key 'translate' given twice in one object")


def test_the_command_pixel_suggests_deletes_that_splat(tmp_path, capsys, monkeypatch):
    """pixel --help names the index of a floater and the edit command that deletes it: that
    exact command works and removes exactly that row."""
    import re
    import shlex

    from splatgl.commands import pixel

    text = " ".join(pixel.DESCRIPTION.split())
    suggested = re.search(r"(splatgl edit scene\.ply -o clean\.ply --remove '[^']*')", text)
    assert suggested, "pixel's help no longer suggests an edit command"
    argv = shlex.split(suggested.group(1))
    index = int(re.search(r"index == (\d+)", argv[-1]).group(1))
    save_scene(tmp_path / "scene.ply", random_scene(index + 10, seed=4))
    monkeypatch.chdir(tmp_path)
    assert main(argv[1:]) == 0
    capsys.readouterr()
    before, after = load_scene(tmp_path / "scene.ply"), load_scene(tmp_path / "clean.ply")
    assert np.array_equal(after.means, np.delete(before.means, index, axis=0))
