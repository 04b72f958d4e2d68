"""What ``edit --allow-empty`` writes (a .ply or .spz of zero splats) splatgl reads back where a
scene of no splats means something: ``info``, ``convert`` and ``edit``; a renderer refuses it in
one line (issue 38, LOW: --allow-empty wrote files that splatgl itself then refused)."""

from __future__ import annotations

import json

import pytest

from helpers import random_scene
from splatgl.cli import main
from splatgl.errors import SceneFormatError
from splatgl.formats import load_scene, save_scene


def cli(capsys, *argv):
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


@pytest.mark.parametrize("ext", ["ply", "spz"])
def test_an_empty_scene_written_by_edit_reads_back(tmp_path, capsys, ext):
    save_scene(tmp_path / "in.ply", random_scene(30, degree=1))
    empty = tmp_path / f"e.{ext}"
    code, out, err = cli(capsys, "edit", tmp_path / "in.ply", "-o", empty, "--crop-box",
                         "50,50,50,60,60,60", "--allow-empty")
    assert code == 0 and err == ""
    code, out, err = cli(capsys, "info", empty)
    assert code == 0 and err == "" and out.splitlines()[1:] == [
        "splats:      0 3D Gaussians, SH degree 1", "(an empty scene: no bounds or statistics)"]
    code, out, err = cli(capsys, "info", empty, "--stats", "--json", "-")
    assert code == 0 and json.loads(out)["count"] == 0
    code, out, err = cli(capsys, "convert", empty, tmp_path / "c.ply")
    assert code == 0 and err == "" and load_scene(tmp_path / "c.ply", allow_empty=True).count == 0
    code, out, err = cli(capsys, "convert", empty, tmp_path / "c.sog")
    assert code == 2 and err == (f"splatgl: error: {tmp_path / 'c.sog'}: {empty} holds no splats, "
                                 "and the sog format cannot hold zero splats; nothing written "
                                 "(write .ply or .spz)\n")
    code, out, err = cli(capsys, "edit", empty, tmp_path / "in.ply", "-o", tmp_path / "m.ply",
                         "--sh-degree", "0")
    assert code == 0 and load_scene(tmp_path / "m.ply").count == 30
    with pytest.raises(SceneFormatError, match="no splats"):
        load_scene(empty)  # a caller that cannot take an empty scene: one line
    code, out, err = cli(capsys, "render", empty, "-o", tmp_path / "r.png")
    assert code == 2 and len(err.splitlines()) == 1 and "has no splats" in err
