"""What a user trial found the command line said wrongly or not at all: a missing scene under
the level-of-detail options, options accepted and ignored (--bit-depth on an EXR, --up beside a
camera file, --stereo-layout without --stereo), --version and a bare ``splatgl``, and small
messages (--json FILE, --memory -1G, --under-depth alone, '1 chunks').  Each case is one exact
line on stderr, exit 2, nothing written."""

from __future__ import annotations

import json

import pytest

from splatgl import __version__
from helpers import refused
from splatgl.cli import main
from splatgl.commands._common import demo_scene_path

DEMO = str(demo_scene_path())
SMALL = ["--width", "32", "--height", "24"]


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


BIT_DEPTH = ("; --bit-depth applies to .png or .tif output (8 or 16 bits per channel)")


@pytest.mark.parametrize("extra, out, line", [
    (["--bit-depth", "16"], "b16.exr", "-o {out} is an EXR image, whose channels are float32"),
    (["--bit-depth", "8"], "b8.exr", "-o {out} is an EXR image, whose channels are float32"),
    (["--bit-depth", "16", "--path", "orbit:2"], "v.mp4",
     "-o {out} is a video, whose frames are 8-bit"),
    (["--bit-depth", "16", "--path", "orbit:2", "--format", "exr"], "frames/",
     "-o {out} gets EXR frames, whose channels are float32"),
    (["--bit-depth", "16", "--path", "orbit:2"], "f_%02d.exr",
     "-o {out} gets EXR frames, whose channels are float32"),
])
def test_bit_depth_is_refused_where_the_output_has_none(tmp_path, capsys, extra, out, line):
    """``render -o b16.exr --bit-depth 16`` wrote a float32 EXR and said nothing."""
    target = f"{tmp_path}/{out}"
    depth = extra[1]
    refused(capsys, tmp_path, ["render", "-o", target, *SMALL, *extra],
            f"splatgl: error: --bit-depth {depth}: " + line.format(out=target) + BIT_DEPTH)


def test_bit_depth_still_applies_to_png(tmp_path, capsys):
    assert main(["render", "-o", str(tmp_path / "a.png"), "--bit-depth", "16", *SMALL]) == 0
    assert main(["render", "-o", str(tmp_path / "b.png"), *SMALL]) == 0   # default 8
    # the PNG header's bit depth (IHDR: 8-byte signature, length, type, width, height, depth)
    assert [(tmp_path / n).read_bytes()[24] for n in ("a.png", "b.png")] == [16, 8]
    capsys.readouterr()


def _camera(tmp_path):
    path = tmp_path / "cam.json"
    path.write_text(json.dumps({"width": 32, "height": 24, "fx": 30, "fy": 30, "cx": 16, "cy": 12,
                                "world_to_camera": [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 3],
                                                    [0, 0, 0, 1]]}))
    return path


@pytest.mark.parametrize("command", [["render", "-o", "{tmp}/x.png"], ["pixel", "--at", "1,1"],
                                     ["compare"]])
def test_up_beside_a_camera_file_is_refused(tmp_path, capsys, command):
    """A camera file's pose fixes which way is up: --up was ignored."""
    cam = _camera(tmp_path)
    argv = [a.format(tmp=tmp_path) for a in command]
    refused(capsys, tmp_path, [*argv, "--camera", cam, "--up", "+z"],
            f"splatgl: error: --up +z places the default camera and orbit paths; {cam} brings its "
            "own pose, which fixes which way is up")


@pytest.mark.parametrize("command", [["render", "-o", "{tmp}/x.png"], ["pixel", "--at", "1,1"],
                                     ["compare"]])
def test_stereo_layout_without_stereo_is_refused(tmp_path, capsys, command):
    argv = [a.format(tmp=tmp_path) for a in command]
    refused(capsys, tmp_path, [*argv, *SMALL, "--stereo-layout", "top-bottom"],
            "splatgl: error: --stereo-layout top-bottom lays out a stereo pair: add --stereo IPD, "
            "or leave --stereo-layout out")


def test_stereo_keeps_side_by_side_as_its_default(tmp_path, capsys):
    from splatgl.imagefiles.images import read_image

    assert main(["render", "-o", str(tmp_path / "s.png"), *SMALL, "--stereo", "0.1"]) == 0
    assert read_image(tmp_path / "s.png").shape[:2] == (24, 64)
    assert main(["render", "-o", str(tmp_path / "t.png"), *SMALL, "--stereo", "0.1",
                 "--stereo-layout", "top-bottom"]) == 0
    assert read_image(tmp_path / "t.png").shape[:2] == (48, 32)
    capsys.readouterr()


def test_version_and_a_bare_splatgl(capsys):
    with pytest.raises(SystemExit) as exit_:
        main(["--version"])
    assert exit_.value.code == 0 and capsys.readouterr().out == f"splatgl {__version__}\n"
    assert main([]) == 2   # the commands, where scripts notice: stderr, exit 2
    out, err = capsys.readouterr()
    assert out == "" and err.startswith("usage: splatgl ") and "render" in err and "COMMAND" in err


def test_extent_help_says_what_fast_is(capsys):
    with pytest.raises(SystemExit):
        main(["render", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert "'fast' = the web viewers' approximation: a fixed 2.83 sigma" in text


def test_json_file_not_ending_in_json_says_why(tmp_path, capsys):
    """``info x.ply --json i.txt`` said only 'unrecognized arguments: i.txt'."""
    out = tmp_path / "i.txt"
    hint = (f"; --json takes a FILE ending in .json (or - for standard output), so {out} was not "
            "taken as its FILE (see splatgl info --help)")
    refused(capsys, tmp_path, ["info", DEMO, "--json", out],
            f"splatgl: error: unrecognized arguments: {out}" + hint)
    refused(capsys, tmp_path, ["info", "--json", out, DEMO],
            f"splatgl: error: unrecognized arguments: {DEMO}" + hint)
    refused(capsys, tmp_path, ["info", DEMO, "extra"],   # no --json: no hint
            "splatgl: error: unrecognized arguments: extra (see splatgl info --help)")


@pytest.mark.parametrize("argv, line", [
    (["info", DEMO, "--memory", "-1G"],
     "splatgl: error: --memory: expected a size such as 200M, 1.5G or 4GiB, got '-1G'"),
    (["render", "-o", "x.png", "--near", "-1e3"],
     "splatgl: error: argument --near: must be a finite number > 0, got '-1e3' (see splatgl "
     "render --help)"),
])
def test_a_value_starting_with_minus_reaches_its_option(tmp_path, capsys, argv, line):
    """argparse took -1G for an option: 'argument --memory: expected one argument'."""
    refused(capsys, tmp_path, argv, line)


def test_under_options_without_under_read_as_sentences(tmp_path, capsys):
    out = str(tmp_path / "v.png")
    refused(capsys, tmp_path, ["render", "-o", out, "--under-depth", "z"],
            "splatgl: error: --under-depth describes the --under file; give --under FILE.exr")
    refused(capsys, tmp_path, ["render", "-o", out, "--under-depth", "z", "--under-channel", "D"],
            "splatgl: error: --under-depth and --under-channel describe the --under file; give "
            "--under FILE.exr")
    refused(capsys, tmp_path, ["pixel", "--at", "1,1", "--under-channel", "Z"],   # the default
            "splatgl: error: --under-channel describes the --under file; give --under FILE.exr")


def test_one_chunk_is_singular(tmp_path, capsys):
    assert main(["lod", DEMO, "-o", str(tmp_path / "d.lod.ply")]) == 0
    out = capsys.readouterr().out
    assert "(1 chunk of at most " in out, out


def test_view_refuses_a_renderer_that_cannot_draw_the_projection_before_a_window(tmp_path,
                                                                                  capsys):
    """view --renderer tile on a panorama was refused once the window was open, advising
    'reference', which the viewer does not offer; now before any window (none is needed to
    say so), naming the viewer's renderers only."""
    assert main(["view", DEMO, "--projection", "equirectangular", "--renderer", "tile"]) == 2
    assert capsys.readouterr().err == ("splatgl: error: the tile renderer cannot draw "
                                       "equirectangular images; use --renderer quad or cpu\n")
    assert list(tmp_path.iterdir()) == []


def test_timings_leave_the_capped_sentence_to_its_own_line():
    """--timings printed '1 of 1 views capped, capped the memory bound made the cut ...':
    the streamed frame's capped sentence is said once, on its own line."""
    from types import SimpleNamespace

    from splatgl.commands._common import format_timings

    line = format_timings(SimpleNamespace(cut=0.002, cut_nodes=12, streaming="1 of 1 views capped",
                                          capped="the memory bound made the cut coarser"))
    assert line == "cut 2.0 ms, cut_nodes 12, streaming 1 of 1 views capped (stages total 2.0 ms)"


def test_an_option_value_that_is_one_of_its_choices_may_start_with_a_dash(tmp_path, capsys):
    """--up -y (as the docs write it) was 'argument --up: expected one argument'."""
    assert main(["render", DEMO, "--up", "-y", "-o", str(tmp_path / "a.png"), *SMALL]) == 0
    assert "wrote" in capsys.readouterr().out
