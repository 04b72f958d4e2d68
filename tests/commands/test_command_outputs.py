"""Every command's outputs against the files it reads, and --force (issue 38 item 1): an output
that is one of the command's inputs (the same path, or the same file through a symbolic or hard
link) is refused in one line before any work, --force or not; an existing output is replaced
only with --force, on every command alike.  (The mechanism's units are in test_output_files.py.)"""

from __future__ import annotations

import json
import os

import numpy as np
import pytest

from splatgl.cli import main

BYTES = b"the user's file: must survive"


def run_cli(capsys, *argv):
    rc = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return rc, out, err


def refused(capsys, argv, line):
    """``argv`` exits 2 with exactly ``line`` (after ``splatgl: error: ``) on stderr."""
    rc, out, err = run_cli(capsys, *argv)
    assert (rc, err) == (2, f"splatgl: error: {line}\n"), err
    assert out == ""


def dataset(tmp_path):
    """A one-view transforms.json dataset whose photograph is images/r_0.png."""
    from splatgl.imagefiles.images import write_image

    root = tmp_path / "ds"
    (root / "images").mkdir(parents=True)
    write_image(root / "images" / "r_0.png", np.ones((8, 8, 4), np.float32))
    (root / "transforms.json").write_text(json.dumps({
        "camera_angle_x": 0.8, "frames": [{"file_path": "images/r_0.png", "transform_matrix":
                                           [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 3], [0, 0, 0, 1]]}]}))
    return root


# (argv with {f} for the input that is also the output, the input's file name, the line's
# output option, the input option)
CLASHES = [
    (["compare", "--camera", "{f}", "--json", "{f}"], "cam.json", "--json", "--camera"),
    (["pixel", "--at", "1,1", "--camera", "{f}", "--json", "{f}"], "c.json", "--json", "--camera"),
    (["compare", "--transform", "{f}", "--json", "{f}"], "t.json", "--json", "--transform"),
    (["edit", "{t}/in.ply", "-o", "{t}/out.ply", "--transform", "{f}", "--json", "{f}"], "t.json",
     "--json", "--transform"),
    (["compare", "--image", "{f}", "--heatmap", "{f}"], "qq.png", "--heatmap", "--image"),
    (["compare", "--image", "{f}", "--side-by-side", "{f}", "--force"], "qq.png", "--side-by-side",
     "--image"),
    (["render", "--under", "{f}", "-o", "{f}"], "uu.exr", "-o", "--under"),
    (["render", "--camera", "{f}", "-o", "{f}", "--force"], "v.exr", "-o", "--camera"),
    (["render", "{f}", "-o", "{t}/v.png", "--depth-png", "{f}"], "s.png", "--depth-png", "SCENE"),
    (["info", "{f}", "--json", "{f}", "--force"], "s.json", "--json", "SCENE"),
    (["convert", "{f}", "{f}", "--force"], "s.ply", "", "IN"),
    (["edit", "{f}", "-o", "{f}", "--force", "--decimate", "1"], "s.ply", "-o", "IN"),
    (["path", "interpolate", "--cameras", "{f}", "-o", "{f}", "--force"], "p.json", "-o", "--cameras"),
    (["lod", "{f}", "-o", "{f}", "--force"], "s.lod.ply", "-o", "SCENE"),
    (["bench", "--quick", "{f}", "--json", "{f}", "--force"], "b.json", "--json", "SCENE"),
]


@pytest.mark.parametrize("argv, name, output, source", CLASHES,
                         ids=[f"{a[0]}-{o}-{s}" for a, _, o, s in CLASHES])
def test_an_output_that_is_an_input_is_refused(tmp_path, capsys, argv, name, output, source):
    """Each replaced the input with its output and exited 0."""
    f = tmp_path / name
    f.write_bytes(BYTES)
    (tmp_path / "in.ply").write_bytes(BYTES)
    argv = [a.format(f=f, t=tmp_path) for a in argv]
    where = f"{output} {f}" if output else f"{f}"
    refused(capsys, argv, f"{where}: the same file as {source}; give the output its own name")
    assert f.read_bytes() == BYTES
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted({name, "in.ply"})


@pytest.mark.parametrize("link", ["symbolic", "hard"])
def test_the_same_file_through_a_link_is_refused(tmp_path, capsys, link):
    image = tmp_path / "qq.png"
    image.write_bytes(BYTES)
    out = tmp_path / "heat.png"
    out.symlink_to(image) if link == "symbolic" else os.link(image, out)
    refused(capsys, ["compare", "--image", image, "--heatmap", out, "--force"],
            f"--heatmap {out}: the same file as --image {image}; give the output its own name")
    cam = tmp_path / "cam.json"
    cam.write_bytes(BYTES)
    report = tmp_path / "report.json"
    report.symlink_to(cam) if link == "symbolic" else os.link(cam, report)
    refused(capsys, ["pixel", "--at", "0,0", "--camera", cam, "--json", report, "--force"],
            f"--json {report}: the same file as --camera {cam}; give the output its own name")
    assert image.read_bytes() == BYTES and cam.read_bytes() == BYTES


def test_eval_renders_never_replace_the_photographs(tmp_path, capsys):
    """``eval --renders DIR/images`` replaced every ground-truth photograph with a render."""
    root = dataset(tmp_path)
    photo = root / "images" / "r_0.png"
    before = photo.read_bytes()
    for force in ([], ["--force"]):
        refused(capsys, ["eval", "--dataset", root, "--renders", root / "images", *force],
                f"--renders {photo}: the same file as --dataset; give the output its own name")
        refused(capsys, ["eval", "--dataset", root, "--csv", photo, *force],
                f"--csv {photo}: the same file as --dataset; give the output its own name")
        cameras = root / "transforms.json"
        refused(capsys, ["eval", "--dataset", root, "--json", cameras, *force],
                f"--json {cameras}: the same file as --dataset; give the output its own name")
    assert photo.read_bytes() == before
    assert sorted(p.name for p in (root / "images").iterdir()) == ["r_0.png"]


def _existing(tmp_path):
    """An existing output of every command, each refused without --force."""
    scene = tmp_path / "s.ply"
    scene.write_bytes(BYTES)
    old = tmp_path / "old"
    old.mkdir()
    for name in ("x.png", "x.json", "x.csv", "x.ply", "x.lod.ply", "00000.png", "bench.csv",
                 "popping.json", "interactive.json"):
        (old / name).write_bytes(BYTES)
    return scene, old


EXISTING = [
    (["render", "-o", "{o}/x.png"], "-o {o}/x.png"),
    (["render", "-o", "{t}/new.png", "--depth-png", "{o}/x.png"], "--depth-png {o}/x.png"),
    (["render", "--path", "orbit:2", "-o", "{o}/"], "-o {o}/00000.png"),
    (["compare", "--heatmap", "{o}/x.png"], "--heatmap {o}/x.png"),
    (["compare", "--json", "{o}/x.json"], "--json {o}/x.json"),
    (["pixel", "--at", "0,0", "--json", "{o}/x.json"], "--json {o}/x.json"),
    (["info", "{s}", "--json", "{o}/x.json"], "--json {o}/x.json"),
    (["eval", "--dataset", "{t}/ds", "--csv", "{o}/x.csv"], "--csv {o}/x.csv"),
    (["eval", "--dataset", "{t}/ds", "--renders", "{o}", "--format", "png"], None),
    (["convert", "{s}", "{o}/x.ply"], "{o}/x.ply"),
    (["convert", "{s}", "{t}/y.ply", "--json", "{o}/x.json"], "--json {o}/x.json"),
    (["edit", "{s}", "-o", "{o}/x.ply", "--decimate", "1"], "-o {o}/x.ply"),
    (["lod", "{s}", "-o", "{o}/x.lod.ply"], "-o {o}/x.lod.ply"),
    (["path", "orbit", "-o", "{o}/x.json"], "-o {o}/x.json"),
    (["stress", "--case", "far_1e7", "--json", "{o}/x.json"], "--json {o}/x.json"),
    (["bench", "--quick", "--out", "{o}"], "--out (bench.csv) {o}/bench.csv"),
    (["bench", "--popping", "--out", "{o}", "{s}"], "--out (popping.json) {o}/popping.json"),
    (["bench", "--interactive", "--out", "{o}", "{s}"],
     "--out (interactive.json) {o}/interactive.json"),
]


@pytest.mark.parametrize("argv, where", EXISTING, ids=[" ".join(a[:2]) for a, _ in EXISTING])
def test_an_existing_output_needs_force(tmp_path, capsys, argv, where):
    """``info SCENE --json existing.json`` (and others) replaced any file without --force."""
    scene, old = _existing(tmp_path)
    dataset(tmp_path)
    if where is None:   # eval --renders into a folder holding r_0.png
        (old / "r_0.png").write_bytes(BYTES)
        where = "--renders {o}/r_0.png"
    argv = [a.format(o=old, s=scene, t=tmp_path) for a in argv]
    before = {p.name: p.read_bytes() for p in old.iterdir()}
    refused(capsys, argv, where.format(o=old, t=tmp_path) + ": exists (use --force to replace it)")
    assert {p.name: p.read_bytes() for p in old.iterdir()} == before


def test_force_replaces_an_existing_output(tmp_path, capsys):
    out = tmp_path / "info.json"
    out.write_text("{}")
    from splatgl.commands._common import demo_scene_path

    rc, _, err = run_cli(capsys, "info", demo_scene_path(), "--json", out, "--force")
    assert (rc, err) == (0, "") and json.loads(out.read_text())["count"] > 0


def test_a_link_output_is_written_through_to_its_target(tmp_path, capsys):
    """``-o link.ply --force`` replaced the link with a plain file."""
    from splatgl.commands._common import demo_scene_path

    target = tmp_path / "real.json"
    target.write_text("{}")
    link = tmp_path / "link.json"
    link.symlink_to(target)
    rc, _, err = run_cli(capsys, "info", demo_scene_path(), "--json", link, "--force")
    assert (rc, err) == (0, "") and link.is_symlink()
    assert json.loads(target.read_text())["count"] > 0


@pytest.mark.parametrize("mode, names", [
    (["--quick"], "bench.csv, bench.json and bench.png"),
    (["--popping"], "popping.json"),
    (["--interactive"], "interactive.json and interactive.png"),
    (["--scale", "--sizes", "0.01M"], "scale.json and scale.png"),
    (["--lod", "--sizes", "0.01M"], "lod.json and lod.png"),
])
def test_bench_out_is_checked_before_measuring(tmp_path, capsys, monkeypatch, mode, names):
    """``bench --popping/--interactive --out`` ran the whole benchmark, then crashed on the
    folder and lost the results."""
    from splatgl.api import Renderer
    from splatgl.measure.bench import scale

    def measured(*args, **kwargs):
        raise AssertionError("measured before --out was checked")

    monkeypatch.setattr(Renderer, "__init__", measured)
    monkeypatch.setattr(scale, "run_scale", measured)
    import splatgl.measure.bench.lod_bench as lod_bench
    monkeypatch.setattr(lod_bench, "run_lod", measured)
    scene, _ = _existing(tmp_path)
    bench = ["bench", *mode, "--out"]
    a_file = tmp_path / "results.txt"
    a_file.write_text("x")
    refused(capsys, [*bench, a_file, scene],
            f"--out {a_file}: is a file; --out names a folder for {names}")
    missing = tmp_path / "no" / "out"
    refused(capsys, [*bench, missing, scene], f"--out {missing}: folder {missing.parent} does not exist")
    first = names.split(",")[0].split(" ")[0]
    (tmp_path / "out" / first).mkdir(parents=True)
    refused(capsys, [*bench, tmp_path / "out", scene, "--force"],
            f"--out ({first}) {tmp_path / 'out' / first}: is a directory; give a file name")


def test_convert_to_a_link_writes_its_target(tmp_path, capsys):
    """``convert IN link.ply --force`` left the old target and a plain file instead of the link."""
    from splatgl.commands._common import demo_scene_path
    from splatgl.formats import load_scene

    target = tmp_path / "real.ply"
    target.write_bytes(BYTES)
    link = tmp_path / "link.ply"
    link.symlink_to(target)
    rc, _, err = run_cli(capsys, "convert", demo_scene_path(), link, "--force")
    assert (rc, err) == (0, "") and link.is_symlink()
    assert load_scene(target).count == load_scene(demo_scene_path()).count
    assert sorted(p.name for p in tmp_path.iterdir()) == ["link.ply", "real.ply"]


@pytest.mark.skipif(not os.path.isdir("/proc") or os.statvfs("/proc").f_blocks != 0,
                    reason="no /proc pseudo file system here")
def test_an_output_in_proc_is_not_called_a_full_disk(capsys):
    """``convert IN /proc/x.ply`` said "cannot write (...); the disk is full"."""
    from splatgl.commands._common import demo_scene_path

    refused(capsys, ["convert", demo_scene_path(), "/proc/x.ply"],
            "/proc/x.ply: folder /proc is on a system pseudo file system (such as /proc or /sys), "
            "where no files can be made; give a folder on a disk")
