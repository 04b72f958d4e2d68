"""The conformance kit's folders and files: ``export --force`` replaces only a kit (or a file),
atomically; a shared kit's index.json is checked (plain case names, no path traversal, what is
really wrong); ``render -o`` and ``export`` outputs are checked before any work; ``score``
refuses to score colours below 0 and exits 1 on a failed case."""

from __future__ import annotations

import json
import os
import shutil

import numpy as np
import pytest

from splatgl.cli import main
from splatgl.measure.conformance import cases as cases_module
from splatgl.measure.conformance import export as export_module
from splatgl.measure.conformance.cases import depth_range_case
from splatgl.measure.conformance.export import export_kit
from splatgl.measure.conformance.score import load_index, score_case
from splatgl.errors import SplatglError
from splatgl.imagefiles.images import read_image, write_image


@pytest.fixture(scope="module")
def small_kit(tmp_path_factory):
    """A one-case kit (depth_range, 96x72), exported once; tests copy it before changing it."""
    out = tmp_path_factory.mktemp("small") / "kit"
    export_kit(out, [depth_range_case()])
    return out


def _copy(kit, tmp_path, name="kit"):
    dest = tmp_path / name
    shutil.copytree(kit, dest)
    return dest


def _snapshot(folder):
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


def _one_line(capsys) -> str:
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1, err
    return err


# -- export --force (item 2) -----------------------------------------------------------------

def test_export_force_never_deletes_a_folder_that_is_not_a_kit(tmp_path, capsys, small_kit):
    project = tmp_path / "project"
    (project / "src").mkdir(parents=True)
    (project / "src" / "main.py").write_text("print('mine')\n")
    (project / "pyproject.toml").write_text("[project]\n")
    before = _snapshot(project)
    assert main(["conformance", "export", str(project), "--force", "--no-real", "--no-stress"]) == 2
    err = _one_line(capsys)
    assert f"{project}: not a conformance kit" in err and "never a folder holding anything else" in err
    assert _snapshot(project) == before
    # a kit with a file of the user's added is no longer only a kit
    kit = _copy(small_kit, tmp_path)
    (kit / "cases" / "depth_range" / "notes.txt").write_text("mine")
    assert main(["conformance", "export", str(kit), "--force", "--no-real", "--no-stress"]) == 2
    assert "cases/depth_range holds 'notes.txt'" in _one_line(capsys)
    assert (kit / "cases" / "depth_range" / "notes.txt").read_text() == "mine"
    # an empty folder is not a kit either, and nothing is left beside any of them
    (tmp_path / "empty").mkdir()
    assert main(["conformance", "export", str(tmp_path / "empty"), "--force", "--no-real"]) == 2
    assert "empty folder" in _one_line(capsys)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["empty", "kit", "project"]


def test_export_force_on_the_current_folder_or_a_file_gives_one_line(tmp_path, capsys, monkeypatch,
                                                                     small_kit):
    kit = _copy(small_kit, tmp_path)
    monkeypatch.chdir(kit)
    for target in (".", "..", str(tmp_path)):
        assert main(["conformance", "export", target, "--force", "--no-real", "--no-stress"]) == 2
        assert "is the current folder or holds it" in _one_line(capsys)
    monkeypatch.chdir(tmp_path)
    file = tmp_path / "notes.txt"
    file.write_text("x")
    assert main(["conformance", "export", str(file), "--no-real"]) == 2
    assert _one_line(capsys).endswith(f"{file}: exists (use --force to replace it)")
    # with --force a file is replaced by the kit (the library's call, as the CLI makes it)
    index = export_kit(file, [depth_range_case()], force=True)
    assert file.is_dir() and load_index(file) == index
    assert sorted(p.name for p in tmp_path.iterdir()) == ["kit", "notes.txt"]


def test_export_force_replaces_an_older_kit_and_keeps_it_on_failure(tmp_path, monkeypatch, small_kit):
    kit = _copy(small_kit, tmp_path)
    (kit / "index.json").write_text((kit / "index.json").read_text().replace('"version": 1', '"version": 1 '))
    before = _snapshot(kit)
    calls = []

    def failing_write(path, *args, **kwargs):
        calls.append(path)
        raise KeyboardInterrupt

    monkeypatch.setattr(export_module, "write_image", failing_write)
    with pytest.raises(KeyboardInterrupt):
        export_kit(kit, [depth_range_case()], force=True)
    assert calls and _snapshot(kit) == before                   # the old kit, untouched
    assert sorted(p.name for p in tmp_path.iterdir()) == ["kit"]  # no temporary left
    monkeypatch.undo()
    real_rename = os.rename

    def failing_rename(src, dst):                       # the new kit cannot be put in place
        if ".partial" in str(src):
            raise OSError(5, "Input/output error", str(src))
        real_rename(src, dst)

    monkeypatch.setattr(os, "rename", failing_rename)
    with pytest.raises(SplatglError, match=f"^{kit}: cannot write \\(Input/output error\\)"):
        export_kit(kit, [depth_range_case()], force=True)
    assert _snapshot(kit) == before and sorted(p.name for p in tmp_path.iterdir()) == ["kit"]
    monkeypatch.undo()
    export_kit(kit, [depth_range_case()], force=True)
    assert _snapshot(kit) != before and load_index(kit)["cases"][0]["name"] == "depth_range"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["kit"]


def test_export_to_a_full_disk_names_the_users_folder(tmp_path, full_disk, small_kit):
    kit = _copy(small_kit, tmp_path)
    before = _snapshot(kit)
    with full_disk(3000), pytest.raises(SplatglError) as info:
        export_kit(kit, [depth_range_case()], force=True)
    message = str(info.value)
    assert message.startswith(f"{kit}{os.sep}cases{os.sep}depth_range{os.sep}reference.exr: cannot write"), message
    assert "partial" not in message and "\n" not in message
    assert _snapshot(kit) == before and sorted(p.name for p in tmp_path.iterdir()) == ["kit"]


def test_export_checks_its_folder_before_any_work(tmp_path, capsys, monkeypatch):
    def no_work(*args, **kwargs):
        raise AssertionError("the cases were built before the folder was checked")

    monkeypatch.setattr(cases_module, "all_cases", no_work)
    out = tmp_path / "no" / "kit"
    assert main(["conformance", "export", str(out), "--no-real"]) == 2
    assert f"{out}: folder {out.parent} does not exist" in _one_line(capsys)
    monkeypatch.setattr(os, "access", lambda path, mode: False)   # as a user, not root, sees it
    assert main(["conformance", "export", str(tmp_path / "kit"), "--no-real"]) == 2
    assert f"{tmp_path / 'kit'}: folder {tmp_path} is not writable" in _one_line(capsys)


def test_render_into_an_unwritable_folder_is_refused_before_any_work(tmp_path, capsys, monkeypatch,
                                                                      small_kit):
    monkeypatch.setattr(os, "access", lambda path, mode: False)
    out = tmp_path / "a" / "b"
    assert main(["conformance", "render", str(small_kit), "-o", str(out)]) == 2
    assert f"-o {out}: folder {tmp_path} is not writable" in _one_line(capsys)
    assert not (tmp_path / "a").exists()


def test_export_says_when_the_real_scenes_are_left_out(tmp_path, capsys, monkeypatch):
    monkeypatch.setenv("SPLATGL_SHARED_SCENES", str(tmp_path / "nowhere"))
    monkeypatch.setattr(cases_module, "all_cases", lambda demo, real, stress: [depth_range_case()])
    assert main(["conformance", "export", str(tmp_path / "kit"), "--no-stress"]) == 0
    err = capsys.readouterr().err
    note = [line for line in err.splitlines() if line.startswith("note:")]
    assert len(note) == 1 and "3 real-scene cases left out" in note[0], err
    assert "ply/donut_sh0.ply" in note[0] and str(tmp_path / "nowhere") in note[0]
    assert main(["conformance", "export", str(tmp_path / "kit2"), "--no-real"]) == 0
    assert "note:" not in capsys.readouterr().err


# -- a shared kit's index.json (item 7 and the LOW messages) ---------------------------------

def _with_index(tmp_path, small_kit, change):
    kit = _copy(small_kit, tmp_path)
    index = json.loads((kit / "index.json").read_text())
    index = change(index)
    (kit / "index.json").write_text(json.dumps(index))
    return kit


@pytest.mark.parametrize("name", ["../escaped", "/tmp/escaped", "sub/escaped", "..", ".hidden",
                                  "a\\b", "", 7])
def test_a_case_name_that_is_not_a_plain_name_is_refused(tmp_path, capsys, small_kit, name):
    def rename(index):
        index["cases"][0]["name"] = name
        return index

    kit = _with_index(tmp_path, small_kit, rename)
    out = tmp_path / "out"
    assert main(["conformance", "render", str(kit), "-o", str(out)]) == 2
    err = _one_line(capsys)
    assert f"{kit / 'index.json'}: case 0: field 'name' {name!r}: not a plain name" in err, err
    assert not out.exists() and not (tmp_path / "escaped.exr").exists()
    assert main(["conformance", "score", str(kit), "--images", str(tmp_path)]) == 2
    assert "not a plain name" in _one_line(capsys)


@pytest.mark.parametrize("field, value", [("scene", "../../etc/passwd"), ("camera", "/etc/hosts"),
                                          ("reference_exr", "C:\\x.exr")])
def test_a_case_file_outside_the_kit_is_refused(tmp_path, small_kit, field, value):
    def move(index):
        index["cases"][0][field] = value
        return index

    kit = _with_index(tmp_path, small_kit, move)
    with pytest.raises(SplatglError, match=f"case 0 \\(depth_range\\): field '{field}' .*not a relative "
                                           "path inside the kit"):
        load_index(kit)


@pytest.mark.parametrize("index, why", [
    ([], "not a conformance index (the JSON is a list, not an object)"),
    ({"version": 1}, "not a conformance index (field 'cases' missing)"),
    ({"cases": {"a": 1}}, "not a conformance index (field 'cases' is an object, not a list)"),
    ({"cases": [3]}, "case 0 is a number, not an object"),
    ("{", "not valid JSON (Expecting property name enclosed in double quotes at line 1 column 2)"),
])
def test_an_invalid_index_says_what_is_wrong(tmp_path, index, why):
    (tmp_path / "index.json").write_text(index if isinstance(index, str) else json.dumps(index))
    with pytest.raises(SplatglError) as info:
        load_index(tmp_path)
    assert str(info.value) == f"{tmp_path / 'index.json'}: {why}"


def test_a_case_missing_a_field_or_named_twice_is_refused(tmp_path, small_kit):
    def drop(index):
        del index["cases"][0]["width"]
        return index

    with pytest.raises(SplatglError, match=r"case 0 \(depth_range\): field 'width' missing"):
        load_index(_with_index(tmp_path / "a", small_kit, drop))
    with pytest.raises(SplatglError, match=r"case 1 \(depth_range\): field 'name' 'depth_range': named twice"):
        load_index(_with_index(tmp_path / "b", small_kit,
                               lambda i: dict(i, cases=i["cases"] * 2)))


# -- render -o checked before any work (tracebacks) -------------------------------------------

def test_render_output_clashes_are_refused_before_any_work(tmp_path, capsys, small_kit):
    kit = _copy(small_kit, tmp_path)
    before = _snapshot(kit)
    assert main(["conformance", "render", str(kit), "-o", str(kit)]) == 2
    assert f"-o {kit}: is the kit's folder" in _one_line(capsys)
    # a case named "reference" rendered into its own case folder would overwrite the reference
    index = json.loads((kit / "index.json").read_text())
    index["cases"][0]["name"] = "reference"
    (kit / "index.json").write_text(json.dumps(index))
    before = _snapshot(kit)
    out = kit / "cases" / "depth_range"
    assert main(["conformance", "render", str(kit), "-o", str(out)]) == 2
    assert f"-o {out}: is inside the kit's folder" in _one_line(capsys)
    linked = tmp_path / "linked"                # an image that is a link to the kit's reference
    linked.mkdir()
    (linked / "reference.exr").symlink_to(out / "reference.exr")
    assert main(["conformance", "render", str(kit), "-o", str(linked), "--force"]) == 2
    assert "the same file as the kit's file" in _one_line(capsys)
    assert _snapshot(kit) == before
    assert main(["conformance", "render", str(kit), "-o", "/proc/no/such"]) == 2
    assert _one_line(capsys).startswith("splatgl: error: -o /proc/no/such: ")
    file = tmp_path / "file.exr"
    file.write_bytes(b"x")
    assert main(["conformance", "render", str(kit), "-o", str(file)]) == 2
    assert f"-o {file}: is a file" in _one_line(capsys)
    taken = tmp_path / "taken"
    taken.mkdir()
    (taken / "reference.exr").write_bytes(b"mine")
    assert main(["conformance", "render", str(kit), "-o", str(taken)]) == 2
    assert "exists (use --force to replace it)" in _one_line(capsys)
    assert (taken / "reference.exr").read_bytes() == b"mine"


def test_score_json_may_not_be_a_kit_file(tmp_path, capsys, small_kit):
    kit = _copy(small_kit, tmp_path)
    before = _snapshot(kit)
    camera = kit / "cases" / "depth_range" / "camera.json"
    assert main(["conformance", "score", str(kit), "--images", str(tmp_path), "--json", str(camera),
                 "--force"]) == 2
    assert "the same file as the kit's file" in _one_line(capsys)
    assert _snapshot(kit) == before


# -- score: colours below 0 (MED) ------------------------------------------------------------

def test_an_image_with_colours_below_zero_fails_unscored(tmp_path, small_kit):
    entry = load_index(small_kit)["cases"][0]
    ref = read_image(small_kit / entry["reference_exr"])[..., :4].copy()
    bad = ref.copy()
    bad[..., :3] = -5.0                       # RGB -5 under the reference's own alpha
    write_image(tmp_path / "depth_range.exr", bad)
    score = score_case(small_kit, tmp_path, entry, False)
    assert score.status == "fail" and score.psnr is None and score.off_4 is None
    assert score.explanation.startswith("colours below 0 at ") and "down to -5" in score.explanation
    # float noise just below 0 is scored as usual
    ref[..., :3] -= 1e-4
    write_image(tmp_path / "depth_range.exr", np.ascontiguousarray(ref))
    score = score_case(small_kit, tmp_path, entry, False)
    assert score.status == "pass" and score.psnr > 60
