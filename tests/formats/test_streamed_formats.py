"""Level-of-detail scene formats read and written in chunks (issue 41 item 4): PlayCanvas
Streamed SOG (``lod-meta.json``, :mod:`splatgl.formats.streamed_sog`, written by
:mod:`splatgl.lod.streamed_sog_write`) and XGrids LCC (:mod:`splatgl.formats.lcc`, from files
written per the white paper's layout by tests/lcc_files.py).  Interoperability with
splat-transform: tests/formats/test_interop_streamed.py."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest
from scipy.spatial import cKDTree

from helpers import random_scene
from lcc_files import write_lcc
from splatgl.cli import main
from splatgl.errors import SceneFormatError, SplatglError
from splatgl.formats import detect_format, load_scene, save_scene, sog_write
from splatgl.formats import lcc, streamed_sog
from splatgl.lod.build import build_hierarchy
from splatgl.lod import streamed_sog_write as writer


def _scene(n=1500, degree=0, seed=3):
    s = random_scene(n, seed, degree, wild_colors=0.0, log_scale=(-4.0, 0.5))
    return dataclasses.replace(s, opacity_logits=np.clip(s.opacity_logits, -5.0, 5.0))


def _matched(got, want, tol):
    """Rows of ``want`` nearest each row of ``got`` (one to one, within ``tol``)."""
    dist, rows = cKDTree(want.means).query(got.means)
    assert dist.max() <= tol and len(set(rows)) == got.count
    return want.subset(rows)


@pytest.fixture(scope="module")
def written(tmp_path_factory):
    scene = _scene()
    tree = build_hierarchy(scene, 4)
    out = tmp_path_factory.mktemp("ssog") / "lod-meta.json"
    meta = writer.write_streamed_sog(out, tree, chunk_splats=256)
    return scene, tree, out, meta


def test_streamed_sog_round_trip(written):
    """Level l holds the hierarchy's level l whole; chunks address their rows; level 0 is the
    scene within SOG's quantisation; each chunk's box holds its splats."""
    scene, tree, out, meta = written
    lod = streamed_sog.read_structure(out)
    assert detect_format(out).NAME == "streamed-sog"
    assert lod.levels == meta["lodLevels"] == 5  # 4^4 <= 256 leaves a chunk
    assert lod.counts == tuple(tree.level_size(level) for level in range(5))
    assert len(lod.chunks) == 6  # 1500 leaves in chunks of 256
    full = load_scene(out)
    assert full.count == scene.count
    bound = sog_write.error_bounds(scene)["position"]
    ref = _matched(full, scene, bound)
    np.testing.assert_allclose(full.opacities, ref.opacities, atol=1 / 255 + 1e-6)
    for level in range(lod.levels):
        got = lod.load(level)
        want = tree.nodes.subset(np.arange(tree.offsets[level], tree.offsets[level + 1]))
        assert got.count == want.count
        _matched(got, want, sog_write.error_bounds(want)["position"])
    for k, chunk in enumerate(lod.chunks):
        part = lod.load(0, [k])
        assert part.count == chunk.count(0)
        assert (part.means >= chunk.bound_min - 1e-5).all() and (part.means <= chunk.bound_max + 1e-5).all()


@pytest.mark.slow
def test_cli_writes_refuses_and_replaces_whole(tmp_path, capsys):
    """`splatgl lod S -o DIR/lod-meta.json` writes; again refuses without --force (nothing
    touched); --force replaces the whole output (no unit folder of the old one left, no staging
    folder); info prints the splats per level."""
    src = tmp_path / "s.ply"
    save_scene(src, _scene(900))
    out = tmp_path / "out" / "lod-meta.json"
    out.parent.mkdir()
    assert main(["lod", str(src), "-o", str(out), "--chunk-splats", "64", "--branching", "2"]) == 0
    before = {p: p.read_bytes() for p in out.parent.rglob("*") if p.is_file()}
    assert len(json.loads(out.read_text())["filenames"]) == 6
    assert main(["lod", str(src), "-o", str(out)]) == 2
    assert "exists (use --force to replace it)" in capsys.readouterr().err
    assert {p: p.read_bytes() for p in out.parent.rglob("*") if p.is_file()} == before
    assert main(["lod", str(src), "-o", str(out), "--force", "--chunk-splats", "600"]) == 0
    meta = json.loads(out.read_text())
    assert sorted(p.name for p in out.parent.iterdir()) == sorted(
        ["lod-meta.json", *{n.split("/")[0] for n in meta["filenames"]}])
    assert meta["lodLevels"] == 5 and load_scene(out).count == 900
    assert main(["convert", str(out), str(tmp_path / "back.ply")]) == 0  # any reader's scene
    assert load_scene(tmp_path / "back.ply").count == 900
    capsys.readouterr()
    assert main(["info", str(out)]) == 0
    text = capsys.readouterr().out
    counts = ", ".join(f"{i}: {c}" for i, c in enumerate(meta["counts"]))
    assert f"levels:      5 in 2 chunks, splats per level {counts}" in text


def test_a_streamed_sog_over_the_memory_bound_is_refused_before_the_build(tmp_path, capsys):
    """lod -o DIR/lod-meta.json built in memory whatever --memory said (812 MB at --memory 100M
    for 1.5M splats, not a word); it is now refused, as convert refuses formats written whole."""
    from splatgl.edit.streamed import Source
    from splatgl.lod.budget import format_size

    src = tmp_path / "s.ply"
    save_scene(src, _scene(900))
    out = tmp_path / "out" / "lod-meta.json"
    out.parent.mkdir()
    need = writer.BUILD_COPIES * Source(src).in_memory_bytes()
    assert main(["lod", str(src), "-o", str(out), "--memory", "20K"]) == 2
    assert capsys.readouterr().err == (
        f"splatgl: error: {out}: a Streamed SOG is built from the whole scene in memory (about "
        f"{format_size(need)}, over --memory 20 KiB); write a .lod.ply, which builds within it, "
        "or give a larger --memory\n")
    assert list(out.parent.iterdir()) == []
    assert main(["lod", str(src), "-o", str(out), "--memory", "10M"]) == 0


def test_stray_unit_folder_is_never_replaced(tmp_path, capsys):
    src = tmp_path / "s.ply"
    save_scene(src, _scene(300))
    (tmp_path / "out" / "0_0").mkdir(parents=True)
    out = tmp_path / "out" / "lod-meta.json"
    assert main(["lod", str(src), "-o", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.endswith(f"{out.parent / '0_0'}: exists and lod-meta.json does not name it; "
                        "remove it or write the Streamed SOG to another folder")
    assert not out.exists()
    assert main(["lod", str(src), "-o", str(tmp_path / "x.ply"), "--chunk-splats", "9"]) == 2
    assert "--chunk-splats applies to Streamed SOG output" in capsys.readouterr().err


@pytest.mark.parametrize("error", [OSError(28, "No space left on device"), KeyboardInterrupt()])
def test_failed_write_leaves_the_old_output(written, tmp_path, monkeypatch, error):
    """A write failing midway (a full disk; Ctrl-C, or SIGTERM as splatgl.cli raises it) leaves
    the old output whole and no staging folder."""
    scene, tree, out, _ = written
    folder = tmp_path / "o"
    folder.mkdir()
    target = folder / "lod-meta.json"
    writer.write_streamed_sog(target, tree, chunk_splats=256)
    before = {p: p.read_bytes() for p in folder.rglob("*") if p.is_file()}
    calls = []

    def failing(rgba):
        calls.append(1)
        if len(calls) > 8:
            raise error
        return real(rgba)

    real = writer.webp.encode
    monkeypatch.setattr(writer.webp, "encode", failing)
    with pytest.raises(SplatglError if isinstance(error, OSError) else KeyboardInterrupt,
                       match="lod-meta.json: cannot write" if isinstance(error, OSError) else None):
        writer.write_streamed_sog(target, tree, chunk_splats=256)
    assert {p: p.read_bytes() for p in folder.rglob("*") if p.is_file()} == before


def test_sog_version_message(tmp_path):
    """An unsupported SOG version no longer lists itself as supported."""
    path = tmp_path / "meta.json"
    path.write_text('{"version": 1, "means": {}}')
    with pytest.raises(SceneFormatError) as err:
        load_scene(path)
    assert str(err.value) == (f"{path}: field 'version': SOG version 1 is not supported "
                              "(supported: 2, and version 1, which has no 'version' key and "
                              "gives means.shape)")


def test_convert_to_a_streamed_sog_name_says_how(tmp_path, capsys):
    """`convert` named lod-meta.json wrote a plain SOG folder under that name; it now refuses,
    naming the command that writes one."""
    save_scene(tmp_path / "s.ply", _scene(10))
    assert main(["convert", str(tmp_path / "s.ply"), str(tmp_path / "lod-meta.json")]) == 2
    assert capsys.readouterr().err.strip().endswith(
        "lod-meta.json: a Streamed SOG holds levels of detail: write it with 'splatgl lod SCENE "
        "-o DIR/lod-meta.json'")
    assert not (tmp_path / "lod-meta.json").exists()


BAD_MANIFESTS = [
    ({"version": 2}, "field 'version': Streamed SOG version 2 is not supported (supported: 1, or none)"),
    ({"lodLevels": 0}, "field 'lodLevels': 0 is not an integer >= 1"),
    ({"counts": [5, 2]}, "field 'counts': counts [5, 2] disagree with the tree's [4, 1]"),
    ({"filenames": ["../0_0/meta.json"]}, "field 'filenames': unit '../0_0/meta.json' is not a "
                                          "relative path to a SOG meta.json inside the folder"),
    ({"tree": {"bound": {"min": [0, 0], "max": [1, 1, 1]}, "lods": {}}},
     "field 'tree.bound': expected three finite numbers in min and max"),
    ({"tree": {"bound": {"min": [0, 0, 0], "max": [1, 1, 1]},
               "lods": {"0": {"file": 3, "offset": 0, "count": 4}}}},
     "field 'tree.lods.0.file': file 3 is not one of the 1 filenames"),
]


@pytest.mark.parametrize("change,message", BAD_MANIFESTS)
def test_bad_manifest_is_one_line(tmp_path, change, message, capsys):
    (tmp_path / "0_0").mkdir()
    save_scene(tmp_path / "0_0" / "meta.json", _scene(4))
    meta = {"version": 1, "counts": [4, 1], "lodLevels": 2, "filenames": ["0_0/meta.json"],
            "tree": {"bound": {"min": [0, 0, 0], "max": [1, 1, 1]},
                     "lods": {"0": {"file": 0, "offset": 0, "count": 4},
                              "1": {"file": 0, "offset": 0, "count": 1}}}}
    path = tmp_path / "lod-meta.json"
    path.write_text(json.dumps({**meta, **change}))
    assert main(["info", str(path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].endswith(f"{path}: {message}")


# --- LCC ------------------------------------------------------------------------------------


def _lcc_levels(degree):
    scene = _scene(600, degree)
    dc = np.clip(scene.sh[:, :1], -0.45 / 0.2821, 0.45 / 0.2821)  # LCC's 8-bit colour range
    scene = dataclasses.replace(scene, sh=np.concatenate([dc, scene.sh[:, 1:]], 1))
    return [scene, scene.subset(np.arange(0, 600, 4))]


@pytest.mark.parametrize("degree", [0, 3])
def test_lcc_from_the_white_paper_layout(tmp_path, degree, capsys):
    """Every level reads back (PLY axes) within LCC's quantisation; units are chunks with
    boxes holding their splats; the environment comes with every level; info lists levels."""
    levels = _lcc_levels(degree)
    env = _scene(20, degree, seed=9)
    env = dataclasses.replace(env, sh=levels[0].sh[:20])
    path = write_lcc(tmp_path, levels, cells=3, environment=env)
    assert detect_format(path).NAME == "lcc"
    lod = lcc.read_structure(path)
    assert lod.levels == 2 and lod.counts == (600, 150) and len(lod.chunks) == 9
    for level, want in enumerate(levels):
        got = lod.load(level, environment=False)
        ref = _matched(got, want, 1e-5)
        np.testing.assert_allclose(got.opacities, ref.opacities, atol=0.5 / 255 + 1e-6)
        np.testing.assert_allclose(got.sh[:, 0], ref.sh[:, 0], atol=0.5 / 255 / 0.2821 + 1e-5)
        if degree:
            assert np.abs(got.sh[:, 1:] - ref.sh[:, 1:]).max() < 0.01
        dots = np.abs((got.rotations * ref.rotations).sum(1))
        assert dots.min() > 0.999
        span = levels[0].scales.max(0) - levels[0].scales.min(0)
        assert (np.abs(got.scales - ref.scales) <= span / 65535 + 1e-6).all()
    for k, chunk in enumerate(lod.chunks):
        part = lod.load(0, [k], environment=False)
        assert (part.means >= chunk.bound_min - 1e-4).all() and (part.means <= chunk.bound_max + 1e-4).all()
    full = load_scene(path)
    assert full.count == 620
    _matched(full.subset(np.arange(600, 620)), env, 1e-5)
    assert main(["info", str(path)]) == 0
    assert "levels:      2 in 9 chunks, splats per level 0: 600, 1: 150" in capsys.readouterr().out


def _lcc_bad(tmp_path, what):
    path = write_lcc(tmp_path, _lcc_levels(0), cells=2)
    if what == "index":
        (tmp_path / "Index.bin").write_bytes((tmp_path / "Index.bin").read_bytes()[:-3])
        return path, ("Index.bin: field 'indexDataSize': 141 bytes is not a whole number of "
                      "36-byte units for 2 levels")
    if what == "data":
        (tmp_path / "Data.bin").write_bytes((tmp_path / "Data.bin").read_bytes()[:100])
        return path, "Index.bin: unit 0 names bytes past the end of Data.bin (100 bytes)"
    if what == "missing":
        (tmp_path / "Index.bin").unlink()
        return path, "meta.lcc: no Index.bin beside it"
    meta = json.loads(path.read_text())
    meta["splats"] = [1, 2]
    path.write_text(json.dumps(meta))
    return path, "meta.lcc: field 'splats': splats [1, 2] disagree with Index.bin's [600, 150]"


@pytest.mark.parametrize("what", ["index", "data", "missing", "splats"])
def test_bad_lcc_is_one_line(tmp_path, what, capsys):
    path, message = _lcc_bad(tmp_path, what)
    assert main(["info", str(path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and message in err[0], err


# --- damage: load or one clean line (the rules of tests/formats/test_formats_fuzz.py) ----------------


@pytest.mark.slow
def test_damaged_manifest_and_lcc_files(written, tmp_path):
    """JSON damage to lod-meta.json and meta.lcc, truncation and corruption of Index.bin and
    Data.bin: a scene or SceneFormatError with one clean line, nothing else."""
    from helpers import check_case, corruptions, truncations
    from test_formats_fuzz_new import json_damage

    rng = np.random.default_rng(7)
    _, tree, _, _ = written
    folder = tmp_path / "s"
    folder.mkdir()
    target = folder / "lod-meta.json"
    writer.write_streamed_sog(target, tree, chunk_splats=512)
    meta = json.loads(target.read_text())
    for k, damaged in enumerate(json_damage(meta, rng, 40)):
        check_case(load_scene, target, json.dumps(damaged).encode(), f"lod-meta.json case {k}")
    path = write_lcc(tmp_path / "l", _lcc_levels(3), cells=2)
    meta = json.loads(path.read_text())
    for k, damaged in enumerate(json_damage(meta, rng, 40)):
        check_case(load_scene, path, json.dumps(damaged).encode(), f"meta.lcc case {k}")
    path.write_text(json.dumps(meta))
    for name in ("Index.bin", "Data.bin", "Shcoef.bin"):
        data = (path.parent / name).read_bytes()
        cases = [data[:n] for n in truncations(len(data), 6, rng)] + corruptions(data, 6, rng)
        for k, blob in enumerate(cases):
            (path.parent / name).write_bytes(blob)
            check_case(load_scene, path, path.read_bytes(), f"{name} case {k}")
        (path.parent / name).write_bytes(data)
