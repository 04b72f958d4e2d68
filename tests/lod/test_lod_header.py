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
