"""Streamed .splat and .compressed.ply outputs of edit and convert --memory (issue 41 item 5):
blocks of a few rows (and sorted runs as small, for the compressed PLY's Morton order on disk)
write the in-memory writer's file byte for byte; nothing is left on a failure."""

from __future__ import annotations

import os
import signal
import warnings

import numpy as np
import pytest

from splatgl.cli import main
from splatgl.edit import CropBox, Filter, ShDegree, edit_files
from splatgl.edit import streamed, streamed_edit, streamed_outputs
from splatgl.edit.streamed_convert import convert_file
from splatgl.errors import SplatglError
from splatgl.formats.convert import convert
from splatgl.scene.splats import Scene, SplatKind

from test_edit_streamed import ROWS, TURN, _ply, _scene

OUTPUTS = [".splat", ".compressed.ply"]


@pytest.fixture
def small_blocks(monkeypatch):
    seen = []
    decode = streamed.Source.decode

    def counting(self, records, start):
        seen.append(records.shape[0])
        return decode(self, records, start)

    monkeypatch.setattr(streamed_edit, "block_rows", lambda *a, **k: ROWS)
    monkeypatch.setattr(streamed.Source, "decode", counting)
    return seen


@pytest.mark.parametrize("ext", OUTPUTS)
@pytest.mark.parametrize("ops, transforms, extras", [
    ([CropBox((-0.9, -1, -1), (1, 1, 1))], None, "label"),
    ([Filter("index < 200 or index > 350"), ShDegree(1)], [TURN], "normals"),
])
def test_edit_writes_the_in_memory_file(tmp_path, small_blocks, ext, ops, transforms, extras):
    src = _ply(tmp_path, _scene(700, degree=2, extras=extras))
    ref = edit_files([src], tmp_path / f"ref{ext}", ops, transforms)
    got = edit_files([src], tmp_path / f"got{ext}", ops, transforms, memory=1)
    assert small_blocks and max(small_blocks) == ROWS
    assert (tmp_path / f"got{ext}").read_bytes() == (tmp_path / f"ref{ext}").read_bytes()
    assert (got.steps, got.count, got.sh_degree, got.output_bytes, got.notes) == \
        (ref.steps, ref.count, ref.sh_degree, ref.output_bytes, ref.notes)
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(["s.ply", f"ref{ext}",
                                                                 f"got{ext}"])


@pytest.mark.parametrize("ext", OUTPUTS)
def test_convert_writes_the_in_memory_file_and_measures_its_round_trip(tmp_path, small_blocks,
                                                                       ext):
    src = _ply(tmp_path, _scene(600, degree=3, extras="label"))
    caught = []
    for name, fn in (("ref", convert), ("got", convert_file)):
        with warnings.catch_warnings(record=True) as w:
            warnings.simplefilter("always")
            kwargs = {} if fn is convert else {"memory": 1}
            caught.append((fn(src, tmp_path / f"{name}{ext}", sh_degree=2, **kwargs),
                           [str(x.message).replace(f"{name}{ext}", "OUT") for x in w]))
    (ref, ref_w), (got, got_w) = caught
    assert small_blocks
    assert (tmp_path / f"got{ext}").read_bytes() == (tmp_path / f"ref{ext}").read_bytes()
    assert got_w == ref_w
    for key in ("count", "sh_degree_in", "sh_degree_out", "output_bytes", "output_format"):
        assert getattr(got, key) == getattr(ref, key), key
    for key in ("count", "dropped", "color_outside_01", "within_bounds", "sh_degree",
                "bit_exact"):
        assert got.error[key] == ref.error[key], key
    for key in ("position", "scale", "opacity", "rotation", "color", "sh_rest"):
        if ref.error[key] is None:
            assert got.error[key] is None
            continue
        assert got.error[key]["max"] == ref.error[key]["max"]
        assert got.error[key]["mean"] == pytest.approx(ref.error[key]["mean"], rel=1e-12)
        bound = ref.error["bounds"][key]
        assert got.error["bounds"][key] == pytest.approx(bound, rel=1e-6, abs=1e-12)


@pytest.mark.parametrize("ext", OUTPUTS)
def test_cli_convert_and_edit_stream_other_outputs(tmp_path, capsys, small_blocks, ext):
    src = _ply(tmp_path, _scene(300, degree=0))
    for name, memory in (("ref", []), ("got", ["--memory", "1K"])):
        assert main(["convert", str(src), str(tmp_path / f"c{name}{ext}"), *memory]) == 0
        assert main(["edit", str(src), "-o", str(tmp_path / f"e{name}{ext}"), "--crop-sphere",
                     "0,0,0,0.9", *memory]) == 0
    capsys.readouterr()
    assert small_blocks
    for kind in "ce":
        assert (tmp_path / f"{kind}got{ext}").read_bytes() == \
            (tmp_path / f"{kind}ref{ext}").read_bytes()


@pytest.mark.parametrize("ext", OUTPUTS)
@pytest.mark.parametrize("sig, code", [(signal.SIGINT, 130), (signal.SIGTERM, 143), (None, 2)])
def test_a_stopped_or_failed_write_leaves_nothing(tmp_path, capsys, monkeypatch, small_blocks,
                                                  ext, sig, code):
    src = _ply(tmp_path, _scene(600, degree=0))
    (tmp_path / f"o{ext}").write_bytes(b"old")
    calls = []
    name = "encode"
    module = streamed_outputs.splat if ext == ".splat" else streamed_outputs.cpw
    real = getattr(module, name)

    def failing(*args):
        calls.append(1)
        if len(calls) == 2:
            if sig is None:
                raise OSError(28, "No space left on device")
            os.kill(os.getpid(), sig)
        return real(*args)

    monkeypatch.setattr(module, name, failing)
    rc = main(["convert", str(src), str(tmp_path / f"o{ext}"), "--force", "--memory", "1K"])
    err = capsys.readouterr().err
    assert rc == code and len(calls) == 2, err
    if sig is None:
        assert err.startswith(f"splatgl: error: {tmp_path / f'o{ext}'}: cannot write (No space "
                              "left on device)") and err.count("\n") == 1, err
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(["s.ply", f"o{ext}"])
    assert (tmp_path / f"o{ext}").read_bytes() == b"old"


def test_a_scale_splat_cannot_hold_is_named_by_its_row_as_in_memory(tmp_path, small_blocks):
    scene = _scene(40, degree=0)
    logs = scene.log_scales.copy()
    logs[23, 1] = 95.0  # e^95 is beyond float32
    src = _ply(tmp_path, Scene(scene.means, scene.quats, logs, scene.opacity_logits, scene.sh))
    messages = []
    for memory in (None, 1):
        with pytest.raises(SplatglError) as err:
            edit_files([src], tmp_path / "o.splat", [ShDegree(0)], memory=memory)
        messages.append(str(err.value))
    assert messages[1] == messages[0]
    assert "row 23: log-scale 95 is beyond" in messages[0]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["s.ply"]


@pytest.mark.parametrize("ext", OUTPUTS)
def test_surfels_are_refused_before_reading(tmp_path, ext):
    s = _scene(30, degree=0)
    surfels = Scene(s.means, s.quats, s.log_scales[:, :2].copy(), s.opacity_logits, s.sh,
                    SplatKind.SURFEL_2D)
    src = _ply(tmp_path, surfels)
    messages = []
    for memory in (None, 1):
        with pytest.raises(SplatglError) as err:
            edit_files([src], tmp_path / f"o{ext}", [ShDegree(0)], memory=memory)
        messages.append(str(err.value).replace(".o.partial", "o").split(": field")[1])
    assert messages[0] == messages[1]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["s.ply"]


def test_whole_chunks_regroups_pieces_at_chunk_boundaries():
    s = _scene(700, degree=0)
    sizes = [100, 300, 5, 295]
    parts, at = [], 0
    for n in sizes:
        parts.append(s.subset(slice(at, at + n)))
        at += n
    pieces = list(streamed_outputs.whole_chunks(parts))
    assert [p.count for p in pieces] == [256, 256, 188]
    assert np.array_equal(np.concatenate([p.means for p in pieces]), s.means)
