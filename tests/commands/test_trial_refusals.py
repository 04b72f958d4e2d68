"""What a user trial found the command line said wrongly or not at all: a missing scene under
the level-of-detail options, options accepted and ignored (--bit-depth on an EXR, --up beside a
camera file, --stereo-layout without --stereo), --version and a bare ``splatgl``, and small
messages (--json FILE, --memory -1G, --under-depth alone, '1 chunks').  Each case is one exact
line on stderr, exit 2, nothing written."""

from __future__ import annotations

import pytest

from splatgl.cli import main
from splatgl.commands._common import demo_scene_path

DEMO = str(demo_scene_path())
SMALL = ["--width", "32", "--height", "24"]


def refused(capsys, tmp_path, argv, line):
    before = sorted(p.name for p in tmp_path.iterdir())
    rc = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    assert (rc, out, err) == (2, "", line + "\n")
    assert sorted(p.name for p in tmp_path.iterdir()) == before


@pytest.mark.parametrize("argv", [
    ["render", "{scene}", "-o", "{tmp}/z.png", "--memory", "1G"],
    ["render", "{scene}", "-o", "{tmp}/z.png", "--lod-threshold", "2"],
    ["render", "{scene}", "-o", "{tmp}/z.png", "--lod-budget", "20"],
    ["render", "{meta}", "-o", "{tmp}/z.png", "--memory", "1G", "--lod-level", "1"],
    ["render", "{scene}", "--path", "orbit:2", "-o", "{tmp}/f/", "--memory", "1G"],
    ["render", "{scene}", "--path", "orbit:2", "-o", "{tmp}/f/", "--lod-threshold", "2"],
    ["bench", "{scene}", "--memory", "1G"],
    ["view", "{scene}", "--memory", "1G"],
    ["info", "{scene}"],
])
def test_a_missing_scene_is_no_such_file_under_every_option(tmp_path, capsys, argv):
    """Under --memory or --lod-* a missing file was 'not a level-of-detail file', 'is not a
    Streamed SOG' or 'give one level-of-detail file'; info said 'no such file' all along."""
    paths = {"scene": tmp_path / "nothere.lod.ply", "meta": tmp_path / "nothere" / "lod-meta.json",
             "tmp": tmp_path}
    argv = [a.format(**paths) for a in argv]
    missing = next(a for a in argv if "nothere" in a)
    refused(capsys, tmp_path, argv, f"splatgl: error: {missing}: no such file")


def test_level_of_detail_options_on_a_folder_say_so(tmp_path, capsys):
    refused(capsys, tmp_path, ["render", tmp_path, "-o", tmp_path / "z.png", "--memory", "1G"],
            f"splatgl: error: {tmp_path}: is a directory, not a scene file")


