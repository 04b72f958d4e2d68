"""One --json convention (issue 25, item 5): ``--json FILE`` writes FILE (*.json) and still
prints the text report; ``--json -`` or a bare ``--json`` prints only the JSON.  The older
spelling ``info --json SCENE`` keeps working; a name that is not *.json is refused."""

from __future__ import annotations

import json

import pytest

from splatgl.cli import main
from splatgl.commands._common import demo_scene_path

DEMO = str(demo_scene_path())


def run(capsys, *argv):
    rc = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return rc, out, err


@pytest.mark.parametrize("argv", [["info", "--json", DEMO], ["info", DEMO, "--json"],
                                  ["info", DEMO, "--json", "-"], ["info", "--json", "-", DEMO]])
def test_stdout_spellings_print_the_json_alone(capsys, argv):
    rc, out, err = run(capsys, *argv)
    assert rc == 0 and json.loads(out)["count"] == 1604 and err == ""


def test_a_file_gets_the_json_and_the_text_still_prints(capsys, tmp_path):
    report = tmp_path / "info.json"
    rc, out, _ = run(capsys, "info", "--json", report, DEMO)
    assert rc == 0 and json.loads(report.read_text())["count"] == 1604
    assert "1,604" in out or "1604" in out
    assert out.rstrip().endswith(f"wrote {report}")
    rc, out, _ = run(capsys, "compare", "--width", "32", "--height", "24", "--json", tmp_path / "c.json")
    figures = json.loads((tmp_path / "c.json").read_text())
    assert rc == 0 and figures["width"] == 32 and "PSNR" in out and f"wrote {tmp_path / 'c.json'}" in out
    rc, out, _ = run(capsys, "convert", DEMO, tmp_path / "d.ply", "--json", tmp_path / "v.json")
    assert rc == 0 and json.loads((tmp_path / "v.json").read_text())["splats"] == 1604
    assert out.startswith(f"wrote {tmp_path / 'd.ply'}") and f"wrote {tmp_path / 'v.json'}" in out


@pytest.mark.parametrize("argv, line", [
    (["info", DEMO, "--json=report.txt"],
     "splatgl: error: --json report.txt: name the report *.json (or - for standard output)"),
    (["bench", "--scale", "--json"], "splatgl: error: --json: --scale writes its JSON with --out DIR"),
])
def test_bad_json_targets_are_refused_in_one_line(capsys, tmp_path, argv, line):
    rc, out, err = run(capsys, *argv)
    assert (rc, out, err) == (2, "", line + "\n")


def test_json_never_overwrites_a_scene(capsys, tmp_path):
    meta = tmp_path / "meta.json"
    meta.write_text('{"version": 2, "means": {"mins": [0, 0, 0]}}')
    before = meta.read_text()
    rc, _, err = run(capsys, "compare", "--json", meta)   # the older spelling of SCENE --json
    assert rc == 2 and err == (f"splatgl: error: --json {meta}: is a scene (SOG meta.json), not a "
                               "report; put the scene before --json\n")
    rc, _, err = run(capsys, "eval", "--dataset", tmp_path, "--csv", tmp_path / "r.json",
                     "--json", tmp_path / "r.json")
    assert (rc, err) == (2, f"splatgl: error: --json {tmp_path / 'r.json'}: the same file as "
                            "--csv; give the report its own name\n")
    assert meta.read_text() == before


@pytest.mark.parametrize("command, required", [
    ("compare", []), ("eval", ["--dataset", "d"]), ("view", []), ("info", ["s.ply"]),
    ("render", ["-o", "x.png"])])
def test_unknown_options_point_to_the_command_help(capsys, command, required):
    rc, out, err = run(capsys, command, *required, "--no-such-option")
    assert (rc, out) == (2, "")
    assert err == (f"splatgl: error: unrecognized arguments: --no-such-option "
                   f"(see splatgl {command} --help)\n")
