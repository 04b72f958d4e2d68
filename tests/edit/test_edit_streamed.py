"""Memory-bounded edit, convert and info --stats of binary PLY files (issue 41 item 5): a small
--memory on small scenes forces many blocks; the files are the in-memory path's, byte for byte."""

from __future__ import annotations

import signal
import warnings

import numpy as np
import pytest

from splatgl.cli import main
from splatgl.edit import CropBox, CropSphere, Filter, ShDegree, edit_files
from splatgl.edit import streamed, streamed_edit, streamed_stats
from splatgl.edit.streamed_convert import convert_file
from splatgl.errors import SplatglError
from splatgl.formats import ply_write
from splatgl.formats.convert import convert
from splatgl.scene.splats import Scene
from splatgl.scene.transform import SceneTransform

ROWS = 7  # rows per block in these tests


def _scene(n: int, seed: int = 0, degree: int = 1, extras=None, bad: int = 0) -> Scene:
    rng = np.random.default_rng(seed)
    means = rng.uniform(-1, 1, (n, 3)).astype(np.float32)
    quats = rng.normal(size=(n, 4)).astype(np.float32)
    if bad:
        means[rng.choice(n, bad, replace=False), 1] = np.nan
        quats[rng.choice(n, bad, replace=False)] = 0
    ex = None
    if extras == "label":
        ex = np.zeros(n, [("nx", "<f4"), ("ny", "<f4"), ("nz", "<f4"), ("label", "<i2")])
        ex["nx"] = rng.normal(size=n)
        ex["label"] = rng.integers(0, 9, n)
    elif extras == "normals":
        ex = np.zeros(n, [("nx", "<f4"), ("ny", "<f4"), ("nz", "<f4")])
        ex["nz"] = 1
    return Scene(means, quats, rng.normal(-3, 0.4, (n, 3)).astype(np.float32),
                 rng.normal(0, 2, n).astype(np.float32),
                 rng.normal(0, 0.3, (n, (degree + 1) ** 2, 3)).astype(np.float32), extras=ex)


def _ply(tmp_path, scene, name="s.ply"):
    path = tmp_path / name
    ply_write.write(path, scene)
    return path


@pytest.fixture
def small_blocks(monkeypatch):
    """Blocks of ROWS rows, and every block's row count recorded."""
    seen = []
    decode = streamed.Source.decode

    def counting(self, records, start):
        seen.append(records.shape[0])
        return decode(self, records, start)

    monkeypatch.setattr(streamed_edit, "block_rows", lambda *a, **k: ROWS)
    monkeypatch.setattr(streamed_stats, "block_rows", lambda *a, **k: ROWS)
    monkeypatch.setattr(streamed.Source, "decode", counting)
    return seen


TURN = SceneTransform(rotation=np.array([[0, -1, 0], [1, 0, 0], [0, 0, 1]], float),
                      translation=(1, 2, 3), scale=2.0)


@pytest.mark.parametrize("ops, transforms, extras, bad", [
    ([], [TURN], None, 0),
    ([CropBox((-0.5, -1, -1), (0.5, 1, 1))], None, "label", 0),
    ([Filter("opacity > 0.3 and (index < 50 or index > 120)"), ShDegree(0)], None, "normals", 0),
    ([CropSphere((0, 0, 0), 0.8, invert=True), Filter("index < 100", invert=True)], [TURN],
     "normals", 0),
    ([ShDegree(2)], None, None, 5),
    ([Filter("index >= 40")], None, "label", 9),
])
def test_edit_streams_the_in_memory_file_byte_for_byte(tmp_path, small_blocks, ops, transforms,
                                                       extras, bad):
    src = _ply(tmp_path, _scene(200, degree=3 if bad else 1, extras=extras, bad=bad))
    drop = bool(bad)
    ref = edit_files([src], tmp_path / "ref.ply", ops, transforms, drop_invalid=drop)
    got = edit_files([src], tmp_path / "got.ply", ops, transforms, drop_invalid=drop, memory=1)
    assert small_blocks and max(small_blocks) == ROWS  # streamed, a block at a time
    assert (tmp_path / "got.ply").read_bytes() == (tmp_path / "ref.ply").read_bytes()
    assert (got.steps, got.count, got.sh_degree, got.input_counts, got.output_bytes,
            got.notes) == (ref.steps, ref.count, ref.sh_degree, ref.input_counts,
                           ref.output_bytes, ref.notes)


@pytest.mark.parametrize("extras", [("label", "normals"), ("normals", None), ("label", "label")])
def test_merge_streams_each_input(tmp_path, small_blocks, extras):
    """Inputs of different SH degrees and other properties, each placed: the merged file."""
    a = _ply(tmp_path, _scene(60, 1, degree=1, extras=extras[0]), "a.ply")
    b = _ply(tmp_path, _scene(45, 2, degree=2, extras=extras[1]), "b.ply")
    ops = [Filter("index < 20 or index > 70"), ShDegree(1)]
    ref = edit_files([a, b], tmp_path / "ref.ply", ops, [None, TURN])
    got = edit_files([a, b], tmp_path / "got.ply", ops, [None, TURN], memory=1)
    assert small_blocks
    assert (tmp_path / "got.ply").read_bytes() == (tmp_path / "ref.ply").read_bytes()
    assert (got.steps, got.count, got.notes) == (ref.steps, ref.count, ref.notes)


def test_convert_streams_ply_to_ply(tmp_path, small_blocks):
    src = _ply(tmp_path, _scene(150, degree=3, extras="label", bad=4))
    with pytest.warns(UserWarning, match="dropped 8 invalid row"):
        ref = convert(src, tmp_path / "ref.ply", drop_invalid=True, sh_degree=1)
    with pytest.warns(UserWarning, match="dropped 8 invalid row"):
        got = convert_file(src, tmp_path / "got.ply", drop_invalid=True, sh_degree=1, memory=1)
    assert small_blocks
    assert (tmp_path / "got.ply").read_bytes() == (tmp_path / "ref.ply").read_bytes()
    for key in ("count", "sh_degree_in", "sh_degree_out", "output_bytes", "output_format"):
        assert getattr(got, key) == getattr(ref, key)
    ref_e, got_e = ref.error, got.error
    assert got_e["bit_exact"] is False and ref_e["bit_exact"] is False  # SH bands dropped
    for key in ("count", "dropped", "color_outside_01", "bounds", "within_bounds",
                "sh_degree"):
        assert got_e[key] == ref_e[key], key
    for key in ("position", "scale", "opacity", "rotation", "color", "sh_rest"):
        assert got_e[key]["max"] == ref_e[key]["max"]
        assert got_e[key]["mean"] == pytest.approx(ref_e[key]["mean"], rel=1e-12, abs=1e-15)


def test_a_small_memory_is_one_line(tmp_path, capsys, monkeypatch):
    """A budget below what the process holds, for an input that must stream."""
    monkeypatch.setattr(streamed, "resident_now", lambda: 80 << 10)
    src = _ply(tmp_path, _scene(50))
    assert main(["edit", str(src), "-o", str(tmp_path / "o.ply"), "--sh-degree", "0",
                 "--memory", "10K"]) == 2
    assert capsys.readouterr().err == ("splatgl: error: --memory 10 KiB is too small: this "
                                       "process already holds 80 KiB; give at least 40.1 MiB\n")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["s.ply"]


def test_cli_edit_and_convert_stream_within_memory(tmp_path, capsys, small_blocks):
    src = _ply(tmp_path, _scene(100, degree=2, extras="label"))
    assert main(["edit", str(src), "-o", str(tmp_path / "ref.ply"), "--crop-sphere",
                 "0,0,0,0.9"]) == 0
    assert main(["edit", str(src), "-o", str(tmp_path / "got.ply"), "--crop-sphere",
                 "0,0,0,0.9", "--memory", "1K"]) == 0
    assert (tmp_path / "got.ply").read_bytes() == (tmp_path / "ref.ply").read_bytes()
    assert small_blocks
    assert main(["convert", str(src), str(tmp_path / "c.ply"), "--memory", "1K"]) == 0
    out = capsys.readouterr().out
    assert "round trip: bit-exact (every stored value identical)" in out
    assert (tmp_path / "c.ply").read_bytes() == src.read_bytes()


def test_other_inputs_load_whole_and_say_so(tmp_path, capsys):
    src = tmp_path / "s.splat"
    assert main(["convert", str(_ply(tmp_path, _scene(100, degree=0))), str(src)]) == 0
    capsys.readouterr()
    assert main(["edit", str(src), "-o", str(tmp_path / "o.ply"), "--sh-degree", "0",
                 "--memory", "1K"]) == 0
    assert ("note: read and edited in memory (about 10.9 KiB, over --memory 1 KiB): only binary "
            "PLY inputs stream") in capsys.readouterr().out


@pytest.mark.parametrize("command", ["edit", "convert"])
@pytest.mark.parametrize("ext, name", [(".spz", "spz"), (".sog", "sog"), (".glb", "gltf")])
def test_outputs_written_whole_are_refused_over_the_bound(tmp_path, capsys, command, ext, name):
    """What a format written whole takes is counted as it peaks (4.2-5.2x the decoded scene,
    measured), not 2x: a --memory between the two was let through to 2.1-2.6x over it."""
    from splatgl.edit.streamed_outputs import whole_write_bytes
    from splatgl.lod.budget import format_size

    src = _ply(tmp_path, _scene(100))
    out = tmp_path / f"o{ext}"
    argv = [command, str(src), "-o", str(out), "--sh-degree", "1"] if command == "edit" else \
        [command, str(src), str(out)]
    from splatgl.edit.streamed import Source

    need = whole_write_bytes(name, Source(src).in_memory_bytes())   # the decoded scene: 13.3 KiB
    for memory in ("1K", "40K"):                       # 40K: over 2x the scene, under the peak
        assert main(argv + ["--memory", memory]) == 2
        assert capsys.readouterr().err == (
            f"splatgl: error: {out}: the {name} format is written from the whole scene in "
            f"memory (about {format_size(need)}, over --memory {memory[:-1]} KiB); write .ply, "
            ".splat or .compressed.ply, which stream, or give a larger --memory\n")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["s.ply"]


@pytest.mark.parametrize("sig, code", [(signal.SIGINT, 130), (signal.SIGTERM, 143), (None, 2)])
def test_an_interrupted_or_failed_write_leaves_nothing(tmp_path, capsys, monkeypatch,
                                                       small_blocks, sig, code):
    """Ctrl-C, SIGTERM or a full disk after some blocks are written: the old output, no
    temporary; the full disk in one line."""
    import os

    src = _ply(tmp_path, _scene(100))
    (tmp_path / "o.ply").write_bytes(b"old")
    calls = []
    real = streamed.scene_to_vertices

    def failing(block):
        calls.append(1)
        if len(calls) == 4:
            if sig is None:
                raise OSError(28, "No space left on device")
            os.kill(os.getpid(), sig)
        return real(block)

    monkeypatch.setattr(streamed, "scene_to_vertices", failing)
    rc = main(["edit", str(src), "-o", str(tmp_path / "o.ply"), "--sh-degree", "0", "--force",
               "--memory", "1K"])
    err = capsys.readouterr().err
    assert rc == code and len(calls) == 4
    if sig is None:
        assert err.startswith(f"splatgl: error: {tmp_path / 'o.ply'}: cannot write (No space "
                              "left on device)") and err.count("\n") == 1, err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["o.ply", "s.ply"]
    assert (tmp_path / "o.ply").read_bytes() == b"old"


def _info(capsys, *argv):
    assert main(["info", *map(str, argv), "--json"]) == 0
    import json
    return json.loads(capsys.readouterr().out)


@pytest.mark.parametrize("bad", [0, 6])
def test_info_stats_streams_the_same_report(tmp_path, capsys, monkeypatch, small_blocks, bad):
    """Counts, min, max, nonfinite, the box and the overdraw exact; float32 medians exact;
    float64 percentiles within 2^-20 relative; means within rounding."""
    monkeypatch.setattr(streamed_stats, "block_rows", lambda *a, **k: 40)
    scene = _scene(300, degree=1, extras="label", bad=bad)
    src = _ply(tmp_path, scene)
    drop = ["--drop-invalid"] if bad else []
    ref = _info(capsys, src, "--stats", *drop)
    got = _info(capsys, src, "--stats", "--memory", "1K", *drop)
    assert small_blocks and max(small_blocks) == 40

    def close(a, b, path=""):
        if isinstance(a, dict):
            assert a.keys() == b.keys(), path
            for k in a:
                close(a[k], b[k], f"{path}.{k}")
        elif isinstance(a, list):
            assert len(a) == len(b)
            for x, y in zip(a, b):
                close(x, y, path)
        elif isinstance(a, float) and path.split(".")[-1] in ("mean", "fragments", "per_pixel"):
            assert a == pytest.approx(b, rel=1e-12, abs=1e-15), path
        elif isinstance(a, float) and path.split(".")[-1] in ("p1", "median", "p99"):
            assert a == pytest.approx(b, rel=2 ** -20, abs=1e-300), path
        else:
            assert a == b, path

    close(got, ref)
    assert got["opacity"]["median"] == pytest.approx(ref["opacity"]["median"], rel=1e-15)


def edit_peaks(src, ops, folder) -> dict:
    """tracemalloc's peak bytes of ``ops`` on ``src`` in memory and streamed (``--memory`` 1
    byte), as ``{"memory": ..., "streamed": ...}``; the outputs ``memory.ply``, ``streamed.ply``
    in ``folder``."""
    import tracemalloc

    peaks = {}
    for name, memory in (("memory", None), ("streamed", 1)):
        tracemalloc.start()
        edit_files([src], folder / f"{name}.ply", ops, memory=memory)
        peaks[name] = tracemalloc.get_traced_memory()[1]
        tracemalloc.stop()
    return peaks


def test_peak_memory_is_a_few_blocks_not_the_scene(tmp_path, monkeypatch):
    """tracemalloc's peak of a streamed crop + SH cut of a 20,000-splat SH3 file (5 MB of
    records, 6 MB decoded) in blocks of 500 rows, against the in-memory edit's."""
    monkeypatch.setattr(streamed_edit, "block_rows", lambda *a, **k: 500)
    src = _ply(tmp_path, _scene(20000, degree=3, extras="normals"))
    ops = [CropBox((-0.9, -1, -1), (1, 1, 1)), ShDegree(2)]
    peaks = edit_peaks(src, ops, tmp_path)
    assert (tmp_path / "streamed.ply").read_bytes() == (tmp_path / "memory.ply").read_bytes()
    assert peaks["memory"] > 10e6
    assert peaks["streamed"] < 2e6, peaks


@pytest.mark.parametrize("options", [["--spz-version", "2"], ["--spz-axes", "rdf"]])
def test_spz_options_do_not_bypass_the_refusal(tmp_path, capsys, options):
    src = _ply(tmp_path, _scene(100))
    out = tmp_path / "o.spz"
    assert main(["convert", str(src), str(out), *options, "--memory", "1K"]) == 2
    assert capsys.readouterr().err.startswith(f"splatgl: error: {out}: the spz format is "
                                              "written from the whole scene in memory")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["s.ply"]


def test_convert_of_another_input_over_the_bound_says_it_loads_whole(tmp_path, capsys):
    src = tmp_path / "s.splat"
    assert main(["convert", str(_ply(tmp_path, _scene(100, degree=0))), str(src)]) == 0
    capsys.readouterr()
    assert main(["convert", str(src), str(tmp_path / "o.spz"), "--memory", "1K"]) == 0
    err = capsys.readouterr().err
    assert err == (f"splatgl: warning: {src}: converted in memory (about 10.9 KiB, over --memory "
                   "1 KiB): only a binary PLY input streams\n"), err


def test_a_dry_run_reads_every_row_as_in_memory(tmp_path, small_blocks):
    """A streamed --dry-run of an operation that removes nothing still finds a bad row."""
    src = _ply(tmp_path, _scene(50, bad=1))
    for memory in (None, 1):
        with pytest.raises(SplatglError, match=r"s\.ply: field .* \(first at index \d+\)") as err:
            edit_files([src], None, [ShDegree(0)], dry_run=True, memory=memory)
        if memory is None:
            expected = str(err.value)
    assert str(err.value) == expected


def test_a_non_finite_result_is_refused_as_in_memory(tmp_path, small_blocks):
    """Overflows in two fields in different blocks: the same field and row are named."""
    scene = _scene(30, degree=1)
    quats, sh = scene.quats.copy(), scene.sh.copy()
    sh[3] = 3e38     # the rotated SH overflows float32 (block 0)
    quats[12] = 3e38  # so does the rotated quaternion (block 1), an earlier field
    src = _ply(tmp_path, Scene(scene.means, quats, scene.log_scales, scene.opacity_logits, sh))
    turn = [SceneTransform(rotation=np.array([[0.6, -0.8, 0], [0.8, 0.6, 0], [0, 0, 1]]))]
    messages = []
    for memory in (None, 1):
        with pytest.raises(SplatglError, match="holds NaN or Inf") as err, \
                warnings.catch_warnings():
            warnings.simplefilter("error")  # no raw NumPy overflow warning either
            edit_files([src], tmp_path / "o.ply", [], turn, memory=memory)
        messages.append(str(err.value))
    assert messages[1] == messages[0] == ("edit: the result's field 'rotation' holds NaN or Inf "
                                          "(first at row 12); nothing written")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["s.ply"]
