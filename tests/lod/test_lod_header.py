"""A ``.lod.ply`` header's shape comment is read in one place (``lod.io.stored_branching``):
the lazy reader, the whole reader and ``info`` refuse a file without it in the same line."""

from __future__ import annotations

import pytest

from splatgl.cli import main
from splatgl.errors import SceneFormatError
from splatgl.lod.io import level_info, read_lod
from splatgl.lod.lazy import LazyLod
from helpers import stream_lod_file

LINE = "not a splatgl LOD file (no 'comment lod branching B' line); build one with 'splatgl lod'"


def _without_branching(tmp_path):
    path = stream_lod_file(tmp_path)
    data = path.read_bytes()
    line = b"comment lod branching 4"
    assert data.count(line) == 1
    path.write_bytes(data.replace(line, b"comment xxxxxxxxxxxxxx"))   # same length, same offsets
    return path


@pytest.mark.parametrize("reader", [LazyLod, read_lod, level_info])
def test_no_branching_comment_is_one_line(tmp_path, reader):
    path = _without_branching(tmp_path)
    with pytest.raises(SceneFormatError, match="no 'comment lod branching B' line") as err:
        reader(path)
    assert str(path) in str(err.value) and "\n" not in str(err.value)


def test_info_names_the_file_and_the_missing_line(tmp_path, capsys):
    path = _without_branching(tmp_path)
    assert main(["info", str(path)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("splatgl: error:") and str(path) in err and LINE in err


def test_convert_and_edit_of_a_level_of_detail_file_say_its_coarser_levels_are_not_written(
        tmp_path, capsys):
    """``convert`` and ``edit`` read a ``.lod.ply`` whole (its leaves) and write a plain scene:
    they say so, with the levels' splat counts from the header, and a plain input gets no
    such note (before, ``convert`` said "bit-exact" of a file that lost its levels)."""
    path = stream_lod_file(tmp_path)
    counts = level_info(path)["counts"]
    coarser = f"its {len(counts) - 1} coarser levels ({sum(counts[1:]):,} splats) are not written"
    assert main(["convert", str(path), str(tmp_path / "c.ply")]) == 0
    err = capsys.readouterr().err
    assert err.startswith(f"splatgl: warning: {path} is a level-of-detail file: its finest level "
                          f"({counts[0]:,} splats) is read; {coarser}") and err.count("\n") == 1
    assert main(["edit", str(path), "-o", str(tmp_path / "e.ply"), "--remove", "opacity < 0"]) == 0
    assert f"  note: {path} is a level-of-detail file" in capsys.readouterr().out
    assert main(["convert", str(tmp_path / "s.ply"), str(tmp_path / "c2.ply")]) == 0
    assert main(["edit", str(tmp_path / "s.ply"), "-o", str(tmp_path / "e2.ply"), "--remove",
                 "opacity < 0"]) == 0
    assert "level-of-detail" not in "".join(capsys.readouterr())
