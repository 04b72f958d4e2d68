"""--remove-floaters and --decimate over --memory (issue 41 item 5): per spatial chunk with a
halo (floaters: the in-memory file, byte for byte) or per chunk alone (decimate: the in-memory
count, a note said once); tiny blocks and chunks force the halo and the exact fallback."""

from __future__ import annotations

import os
import signal

import numpy as np
import pytest

from splatgl.cli import main
from splatgl.edit import (CropBox, Decimate, Filter, RemoveFloaters, ShDegree, edit_files,
                          streamed_edit, streamed_neighbours)
from splatgl.edit.streamed_neighbours import DECIMATE_NOTE
from splatgl.errors import SplatglError
from splatgl.formats import load_scene
from splatgl.scene.splats import Scene, SplatKind

from test_edit_streamed import _ply, _scene, edit_peaks


def _clusters(n: int, floaters: int, seed: int = 0) -> Scene:
    """``n`` splats in a few tight clusters, ``floaters`` of them scattered far out."""
    base = _scene(n, seed, degree=1, extras="label")
    rng = np.random.default_rng(seed)
    centres = rng.normal(size=(5, 3)) * 2
    means = (centres[rng.integers(0, 5, n)] + rng.normal(size=(n, 3)) * 0.1).astype(np.float32)
    means[:floaters] = rng.uniform(-6, 6, (floaters, 3))
    return Scene(means, base.quats, base.log_scales, base.opacity_logits, base.sh,
                 extras=base.extras)


@pytest.fixture
def rows(monkeypatch):
    """Blocks, sort runs and chunks of ``rows.n`` rows."""
    class Rows:
        n = 7
    monkeypatch.setattr(streamed_edit, "block_rows", lambda *a, **k: Rows.n)
    return Rows


@pytest.mark.parametrize("chunk, ops", [
    (7, [RemoveFloaters(neighbours=8, sigma=1.5, opacity=1.0)]),  # chunks below k: no halos
    (60, [RemoveFloaters(neighbours=4, sigma=1.0, opacity=0.7)]),  # halos
    (60, [CropBox((-5, -5, -5), (5, 5, 5)), RemoveFloaters(neighbours=6, sigma=1.0),
          Filter("index > 30"), RemoveFloaters(neighbours=3, sigma=2.0, opacity=1.0)]),
])
def test_floaters_per_chunk_remove_the_in_memory_set(tmp_path, rows, chunk, ops):
    rows.n = chunk
    src = _ply(tmp_path, _clusters(150 if chunk < 10 else 400, 25))
    ref = edit_files([src], tmp_path / "ref.ply", ops)
    got = edit_files([src], tmp_path / "got.ply", ops, memory=1)
    assert any(s.removed for s in ref.steps if s.name == "remove-floaters")
    assert (tmp_path / "got.ply").read_bytes() == (tmp_path / "ref.ply").read_bytes()
    assert (got.steps, got.count, got.notes) == (ref.steps, ref.count, ref.notes)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["got.ply", "ref.ply", "s.ply"]


@pytest.mark.parametrize("ops", [
    [Decimate(percent=30)],
    [RemoveFloaters(neighbours=4, sigma=1.0), Decimate(count=150), ShDegree(0)],
    [Decimate(percent=50), CropBox((-1, -1, -1), (1, 1, 1))],
])
def test_decimate_per_chunk_keeps_the_count_and_says_so(tmp_path, rows, ops):
    rows.n = 60
    src = _ply(tmp_path, _clusters(400, 10))
    ref = edit_files([src], tmp_path / "ref.ply", ops)
    got = edit_files([src], tmp_path / "got.ply", ops, memory=1)
    j = next(i for i, s in enumerate(ref.steps) if s.name == "decimate")
    assert got.steps[:j + 1] == ref.steps[:j + 1]  # the count merged is the in-memory count
    assert [s.name for s in got.steps] == [s.name for s in ref.steps]
    assert got.notes == ref.notes + (DECIMATE_NOTE.format(rows=60),)
    assert load_scene(tmp_path / "got.ply").count == got.count
    assert (got.sh_degree, got.count > 0) == (ref.sh_degree, True)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["got.ply", "ref.ply", "s.ply"]


def test_a_decimation_that_merges_nothing_streams_every_row(tmp_path, rows):
    src = _ply(tmp_path, _clusters(100, 5))
    ops = [Decimate(count=500), ShDegree(0)]
    ref = edit_files([src], tmp_path / "ref.ply", ops)
    got = edit_files([src], tmp_path / "got.ply", ops, memory=1)
    assert (tmp_path / "got.ply").read_bytes() == (tmp_path / "ref.ply").read_bytes()
    assert (got.steps, got.notes) == (ref.steps, ref.notes)


def test_decimate_chunk_shares_sum_to_the_target(tmp_path, rows):
    """The chunks' shares sum to the target down to one splat a chunk (300 splats in chunks of
    37: 9); below that the chunks would pile up unmerged, so it is refused in one line naming
    the limit, and nothing is written."""
    rows.n = 37
    src = _ply(tmp_path, _clusters(300, 0))
    for op in (Decimate(percent=12.5), Decimate(count=222), Decimate(percent=3),
               Decimate(percent=99), Decimate(count=9)):
        got = edit_files([src], tmp_path / "o.ply", [op], memory=1, force=True)
        assert got.count == op.target(300)
    (tmp_path / "o.ply").unlink()
    for op, asked in ((Decimate(count=8), "8 splats"), (Decimate(percent=1), "1%")):
        with pytest.raises(SplatglError) as err:
            edit_files([src], tmp_path / "o.ply", [op], memory=1)
        assert str(err.value) == (
            f"--decimate to {asked} over --memory leaves {op.target(300)} splats, fewer than the "
            "9 spatial chunks of about 37 splats it merges within (one splat each at least): ask "
            "for at least 9, or give more --memory")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["s.ply"]


def test_cli_edit_streams_floaters_and_says_the_decimation_once(tmp_path, capsys, rows):
    rows.n = 50
    src = _ply(tmp_path, _clusters(300, 12))
    for name, memory in (("ref", []), ("got", ["--memory", "1K"])):
        assert main(["edit", str(src), "-o", str(tmp_path / f"{name}.ply"),
                     "--remove-floaters", "neighbours=4,sigma=1", *memory]) == 0
    capsys.readouterr()
    assert (tmp_path / "got.ply").read_bytes() == (tmp_path / "ref.ply").read_bytes()
    assert main(["edit", str(src), "-o", str(tmp_path / "d.ply"), "--decimate", "40%",
                 "--memory", "1K"]) == 0
    out = capsys.readouterr().out
    assert out.count("note: " + DECIMATE_NOTE.format(rows=50)) == 1, out
    assert "merged" in out and "-> 120" in out
    assert sorted(p.name for p in tmp_path.iterdir()) == ["d.ply", "got.ply", "ref.ply", "s.ply"]


@pytest.mark.parametrize("ops", [["--decimate", "50%"], ["--remove-floaters"]])
def test_a_dry_run_leaves_no_scratch_files(tmp_path, capsys, rows, ops):
    rows.n = 30
    src = _ply(tmp_path, _clusters(120, 8))
    assert main(["edit", str(src), "--dry-run", *ops, "--memory", "1K"]) == 0
    assert main(["edit", str(src), "-o", str(tmp_path / "o.ply"), "--dry-run", *ops,
                 "--memory", "1K"]) == 0
    assert "-> " in capsys.readouterr().out
    assert sorted(p.name for p in tmp_path.iterdir()) == ["s.ply"]


@pytest.mark.parametrize("sig, code", [(signal.SIGINT, 130), (signal.SIGTERM, 143), (None, 2)])
@pytest.mark.parametrize("what", ["decimate", "floaters"])
def test_an_interrupted_chunked_edit_leaves_nothing(tmp_path, capsys, monkeypatch, rows, sig,
                                                    code, what):
    """Ctrl-C, SIGTERM or a full disk while the chunks are worked: the old output, no scratch
    folder; the full disk in one line naming the output."""
    rows.n = 40
    src = _ply(tmp_path, _clusters(300, 8))
    (tmp_path / "o.ply").write_bytes(b"old")
    calls = []
    if what == "decimate":
        real = Decimate.apply

        def stop(self, scene, progress=None):
            calls.append(1)
            if len(calls) == 2:
                _stop(sig)
            return real(self, scene, progress)
        monkeypatch.setattr(Decimate, "apply", stop)
        ops = ["--decimate", "50%"]
    else:
        real = streamed_neighbours._chunk_distances

        def stop(*args):
            calls.append(1)
            if len(calls) == 2:
                _stop(sig)
            return real(*args)
        monkeypatch.setattr(streamed_neighbours, "_chunk_distances", stop)
        ops = ["--remove-floaters"]
    rc = main(["edit", str(src), "-o", str(tmp_path / "o.ply"), *ops, "--force",
               "--memory", "1K"])
    err = capsys.readouterr().err
    assert rc == code and len(calls) == 2, err
    if sig is None:
        assert err == (f"splatgl: error: {tmp_path / 'o.ply'}: cannot write (No space left on "
                       "device)\n"), err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["o.ply", "s.ply"]
    assert (tmp_path / "o.ply").read_bytes() == b"old"


def _stop(sig):
    if sig is None:
        raise OSError(28, "No space left on device")
    os.kill(os.getpid(), sig)


@pytest.mark.slow
def test_peak_memory_is_chunks_not_the_scene(tmp_path, monkeypatch):
    """tracemalloc's peak of floaters then a decimation of a 20,000-splat SH3 file in blocks and
    chunks of 1,000 rows, against the in-memory edit's."""
    monkeypatch.setattr(streamed_edit, "block_rows", lambda *a, **k: 1000)
    base = _clusters(20000, 50)
    rng = np.random.default_rng(1)
    src = _ply(tmp_path, Scene(base.means, base.quats, base.log_scales, base.opacity_logits,
                               rng.normal(0, 0.3, (20000, 16, 3)).astype(np.float32)))
    ops = [RemoveFloaters(neighbours=8), Decimate(percent=50)]
    peaks = edit_peaks(src, ops, tmp_path)
    assert peaks["memory"] > 15e6
    assert peaks["streamed"] < peaks["memory"] / 3, peaks


def _refused_alike(src, out, ops) -> str:
    """The refusal of ``ops`` on ``src``, the same in memory and streamed."""
    messages = []
    for memory in (None, 1):
        with pytest.raises(SplatglError) as err:
            edit_files([src], out, ops, memory=memory)
        messages.append(str(err.value))
    assert messages[1] == messages[0]
    return messages[0]


def test_decimate_refusals_are_the_in_memory_ones(tmp_path, rows):
    """A scale whose moments overflow is named by its row in the scene decimated (after a
    filter), and surfels are refused, as in memory; nothing is left."""
    rows.n = 20
    s = _clusters(120, 0)
    logs = s.log_scales.copy()
    logs[77, 2] = 120.0
    big = _ply(tmp_path, Scene(s.means, s.quats, logs, s.opacity_logits, s.sh), "big.ply")
    surfels = _ply(tmp_path, Scene(s.means, s.quats, s.log_scales[:, :2].copy(),
                                   s.opacity_logits, s.sh, SplatKind.SURFEL_2D), "surfels.ply")
    got = [_refused_alike(src, tmp_path / "o.ply", ops)
           for src, ops in ((big, [Filter("index >= 10"), Decimate(percent=50)]),
                            (surfels, [Decimate(percent=50)]))]
    assert "splat 67 has a scale above e^100" in got[0] and "surfels" in got[1], got
    assert sorted(p.name for p in tmp_path.iterdir()) == ["big.ply", "surfels.ply"]


def test_an_empty_result_after_a_decimation_is_refused_and_leaves_nothing(tmp_path, rows):
    rows.n = 20
    src = _ply(tmp_path, _clusters(100, 0))
    ops = [Decimate(percent=50), CropBox((50, 50, 50), (60, 60, 60))]
    assert _refused_alike(src, tmp_path / "o.ply", ops).startswith("edit: no splats left (crop-box")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["s.ply"]


def test_floaters_of_merged_placed_inputs_with_duplicate_centres(tmp_path, rows):
    """Two inputs, one moved, centres repeated (ties among the neighbours): the in-memory file."""
    rows.n = 45
    a = _clusters(200, 12, seed=1)
    means = a.means.copy()
    means[100:140] = means[60:100]  # duplicates
    a = Scene(means, a.quats, a.log_scales, a.opacity_logits, a.sh, extras=a.extras)
    src_a = _ply(tmp_path, a, "a.ply")
    src_b = _ply(tmp_path, _clusters(150, 9, seed=2), "b.ply")
    ops = [RemoveFloaters(neighbours=5, sigma=1.0, opacity=0.8), Filter("index < 300")]
    from test_edit_streamed import TURN
    ref = edit_files([src_a, src_b], tmp_path / "ref.ply", ops, [None, TURN])
    got = edit_files([src_a, src_b], tmp_path / "got.ply", ops, [None, TURN], memory=1)
    assert next(s for s in ref.steps if s.name == "remove-floaters").removed
    assert (tmp_path / "got.ply").read_bytes() == (tmp_path / "ref.ply").read_bytes()
    assert got.steps == ref.steps


@pytest.mark.parametrize("ops, out", [(["--decimate", "50%"], "o.ply"),
                                      (["--remove-floaters"], "o.ply"),
                                      (["--sh-degree", "0"], "o.compressed.ply")])
def test_no_room_for_the_scratch_files_is_said_before_the_work(tmp_path, capsys, monkeypatch,
                                                               rows, ops, out):
    """A disk without room for the sort's scratch files (twice the records) refuses the edit
    in one line naming the output, before any scratch file is written; the output's old
    contents and the input stay."""
    import collections

    from splatgl.edit import streamed_sort

    rows.n = 40
    src = _ply(tmp_path, _clusters(300, 5))
    (tmp_path / out).write_bytes(b"old")
    usage = collections.namedtuple("usage", "total used free")
    monkeypatch.setattr(streamed_sort.shutil, "disk_usage", lambda p: usage(1 << 40, 0, 1000))
    written = []
    real_cells = streamed_sort._Cells
    monkeypatch.setattr(streamed_sort, "_Cells", lambda *a: written.append(a) or real_cells(*a))
    rc = main(["edit", str(src), "-o", str(tmp_path / out), *ops, "--force", "--memory", "1K"])
    err = capsys.readouterr().err
    assert rc == 2 and not written, err
    assert err.startswith(f"splatgl: error: {tmp_path / out}: cannot write (no room for the "
                          "edit's scratch files beside it: about "), err
    assert err.rstrip().endswith("needed, 1000 B free); the disk is full"), err
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(["s.ply", out])
    assert (tmp_path / out).read_bytes() == b"old"
