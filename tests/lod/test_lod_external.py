"""The out-of-core level of detail (splatgl.lod.external, `splatgl lod --memory`) and lazy
reading of .lod.ply files (splatgl.lod.lazy): issue 41 items 1 and 2."""

from __future__ import annotations

import errno
import os
import signal

import numpy as np
import pytest

from splatgl.cameras.camera import Camera
from splatgl.cameras.poses import look_at
from splatgl.cli import main
from splatgl.errors import SplatglError
from splatgl.formats import load_scene, ply_write
from splatgl.lod import budget, external
from splatgl.lod.budget import Plan, parse_size
from splatgl.lod.build import build_hierarchy
from splatgl.lod.cut import CutData, select_cut_weights
from splatgl.lod.io import read_lod, write_lod
from splatgl.lod.lazy import LazyLod
from splatgl.lod.selection import LodSettings
from splatgl.scene.splats import Scene


def _scene(n: int, seed: int = 0, degree: int = 1, log_scale: float = -3.5) -> Scene:
    rng = np.random.default_rng(seed)
    return Scene(rng.uniform(-1, 1, (n, 3)), rng.normal(size=(n, 4)),
                 rng.normal(log_scale, 0.4, (n, 3)), rng.normal(1, 1, n),
                 rng.normal(0, 0.3, (n, (degree + 1) ** 2, 3)))


def _ply(tmp_path, scene: Scene, name: str = "s.ply"):
    path = tmp_path / name
    ply_write.write(path, scene)
    return path


def _in_memory(src, out, branching: int = 4):
    write_lod(out, build_hierarchy(load_scene(src), branching))
    return out.read_bytes()


def _cli(capsys, *argv):
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


@pytest.mark.parametrize("branching, window, run", [(4, 64, 100), (3, 27, 50), (2, 1024, 300)])
def test_chunked_build_writes_the_in_memory_file_byte_for_byte(tmp_path, branching, window, run):
    """Chunks of B^k leaves are whole subtrees: the same hierarchy, radii and bytes, with many
    chunks and sorted runs shorter than the Morton cells (the radix sort splits them again)."""
    scene = _scene(3000, degree=1)
    means = scene.means.copy()
    means[:700] = means[0]          # one Morton code held by more rows than a run
    means[700:1200] *= 1e-3         # a dense cell, split by the next bits
    src = _ply(tmp_path, Scene(means, scene.quats, scene.log_scales, scene.opacity_logits, scene.sh))
    expected = _in_memory(src, tmp_path / "ref.lod.ply", branching)
    info = external.build_lod_file(src, tmp_path / "o.lod.ply", branching,
                                   lambda record, count: Plan(1 << 30, 1 << 29, window, 97, run))
    assert info["chunks"] == -(-3000 // info["window"]) > 1
    assert (tmp_path / "o.lod.ply").read_bytes() == expected
    tree = read_lod(tmp_path / "o.lod.ply")  # the cut at the leaves draws the plain scene
    leaves = tree.nodes.subset(slice(0, 3000))
    key = lambda s: np.lexsort(np.column_stack([s.means, s.log_scales]).T)  # noqa: E731
    plain = load_scene(src)
    assert np.array_equal(leaves.means[key(leaves)], plain.means[key(plain)])
    assert np.array_equal(leaves.sh[key(leaves)], plain.sh[key(plain)])
    assert sorted(p.name for p in tmp_path.iterdir()) == ["o.lod.ply", "ref.lod.ply", "s.ply"]


def test_cli_builds_within_a_small_memory_budget(tmp_path, capsys, monkeypatch):
    """--memory picks chunks that fit (the process's own memory taken off first)."""
    monkeypatch.setattr(budget, "resident_now", lambda: 80 << 20)
    src = _ply(tmp_path, _scene(20000, degree=1))
    expected = _in_memory(src, tmp_path / "ref.lod.ply")
    code, out, err = _cli(capsys, "lod", src, "-o", tmp_path / "o.lod.ply", "--memory", "130M")
    assert (code, err) == (0, "")
    assert out.startswith(f"wrote {tmp_path / 'o.lod.ply'}: 20,000 leaves, 6,670 parents in 9 "
                          "levels (branching 4) in ")
    assert out.rstrip().endswith("(5 chunks of at most 4,096 leaves; memory budget 130 MiB "
                                 "(--memory))"), out
    assert (tmp_path / "o.lod.ply").read_bytes() == expected


def test_other_formats_are_read_whole_and_the_summary_says_so(tmp_path, capsys):
    src = _ply(tmp_path, _scene(300))
    assert main(["convert", str(src), str(tmp_path / "s.spz")]) == 0
    capsys.readouterr()
    code, out, err = _cli(capsys, "lod", tmp_path / "s.spz", "-o", tmp_path / "o.lod.ply",
                          "--memory", "4G")
    assert (code, err) == (0, "")
    assert out.rstrip().endswith("(s.spz was read whole: --memory bounds the build from a "
                                 "binary PLY)"), out


def test_progress_says_the_time_left(tmp_path, capsys, monkeypatch):
    monkeypatch.setenv("SPLATGL_PROGRESS", "1")
    src = _ply(tmp_path, _scene(2000))
    code, out, err = _cli(capsys, "lod", src, "-o", tmp_path / "o.lod.ply")
    assert code == 0
    assert "lod: memory budget " in err and "of this machine's" in err
    assert "lod s.ply: building: 100.0% (12,000 / 12,000)" in err
    assert ", about " in err and " left" in err


@pytest.mark.parametrize("value, line", [
    ("12Q", "--memory: expected a size such as 200M, 1.5G or 4GiB, got '12Q'"),
    ("0", "--memory: the size must be positive, got '0'"),
    ("1e9", "--memory: expected a size such as 200M, 1.5G or 4GiB, got '1e9'"),
    ("50M", "--memory 50 MiB is too small: this process already holds 80 MiB; give at least 120 MiB"),
])
def test_memory_errors_are_one_line(tmp_path, capsys, monkeypatch, value, line):
    monkeypatch.setattr(budget, "resident_now", lambda: 80 << 20)
    src = _ply(tmp_path, _scene(100))
    code, out, err = _cli(capsys, "lod", src, "-o", tmp_path / "o.lod.ply", "--memory", value)
    assert (code, out, err) == (2, "", f"splatgl: error: {line}\n")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["s.ply"]


def test_sizes_parse():
    assert parse_size("200M") == 200 << 20
    assert parse_size("1.5G") == 3 << 29
    assert parse_size("4GiB") == 4 << 30
    assert parse_size("300000") == 300000
    with pytest.raises(SplatglError):
        parse_size("lots")


def _small_chunks(monkeypatch):
    monkeypatch.setattr("splatgl.lod.budget.plan",
                        lambda b, br, record, count, held=None: Plan(b, b, 64, 97, 100))


@pytest.mark.parametrize("sig, code", [(signal.SIGINT, 130), (signal.SIGTERM, 143)])
def test_ctrl_c_and_sigterm_leave_nothing(tmp_path, capsys, monkeypatch, sig, code):
    """Interrupted in the middle of the chunks: no output, no temporary, no scratch folder."""
    _small_chunks(monkeypatch)
    src = _ply(tmp_path, _scene(1000))
    real = external._Chunks.chunk
    calls = []

    def chunk(self, recs):
        calls.append(1)
        if len(calls) == 3:
            os.kill(os.getpid(), sig)
        return real(self, recs)
    monkeypatch.setattr(external._Chunks, "chunk", chunk)
    rc, out, err = _cli(capsys, "lod", src, "-o", tmp_path / "o.lod.ply")
    assert rc == code and len(calls) == 3
    assert sorted(p.name for p in tmp_path.iterdir()) == ["s.ply"]


def test_a_full_disk_is_one_line_and_leaves_nothing(tmp_path, capsys, monkeypatch):
    _small_chunks(monkeypatch)
    src = _ply(tmp_path, _scene(1000))

    def full(self, recs):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), str(self.folder / "000"))
    monkeypatch.setattr(external._Cells, "add", full)
    code, out, err = _cli(capsys, "lod", src, "-o", tmp_path / "o.lod.ply")
    assert (code, out) == (2, "")
    assert err == (f"splatgl: error: {tmp_path / 'o.lod.ply'}: cannot write (No space left on "
                   "device)\n")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["s.ply"]


def test_too_little_disk_is_one_line_before_the_work(tmp_path, capsys, monkeypatch):
    src = _ply(tmp_path, _scene(1000))
    monkeypatch.setattr(external.shutil, "disk_usage", lambda p: type("U", (), {"free": 4096})())
    code, out, err = _cli(capsys, "lod", src, "-o", tmp_path / "o.lod.ply")
    assert (code, out) == (2, "")
    assert err.startswith(f"splatgl: error: {tmp_path / 'o.lod.ply'}: cannot write: the build "
                          "needs about ") and err.endswith(" beside it (temporary files and the "
                                                           "output), 4 KiB free\n"), err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["s.ply"]


def _far_camera(distance: float) -> Camera:
    return Camera.from_fov(320, 180, 60.0, look_at(np.array([0.0, 0.0, -distance]), np.zeros(3)))


def test_lazy_open_reads_only_what_the_cut_needs(tmp_path):
    """A far view reads the header, a few pages of spheres and the rows it draws: the same cut
    and nodes as the whole file read (cut over the same anchor)."""
    path = tmp_path / "s.lod.ply"
    write_lod(path, build_hierarchy(_scene(100_000, log_scale=-6.0)))
    tree = read_lod(path)
    size = path.stat().st_size
    for distance, band, share in ((200.0, 1.0, 0.02), (60.0, 2.0, 0.15)):
        with LazyLod(path) as lazy:
            assert lazy.bytes_read < 2000  # the header
            rows, weights = lazy.cut(_far_camera(distance), LodSettings(1.0, band=band))
            nodes = lazy.nodes(rows)
            eager = CutData(np.ascontiguousarray((tree.nodes.means.astype(np.float64)
                                                  - lazy.anchor).T, np.float32),
                            tree.radius, tree.offsets, tree.branching, lazy.anchor)
            rows2, weights2 = select_cut_weights(eager, _far_camera(distance), 1.0, band)
            assert np.array_equal(rows, rows2) and 0 < rows.size < 0.1 * tree.nodes.count
            assert (weights is None) == (weights2 is None) and (
                weights is None or np.array_equal(weights, weights2))
            sub = tree.nodes.subset(rows)
            for field in ("means", "quats", "log_scales", "opacity_logits", "sh"):
                assert np.array_equal(getattr(nodes, field), getattr(sub, field)), field
            assert lazy.bytes_read < share * size, (lazy.bytes_read, size)


def test_lazy_reading_needs_the_spheres_and_says_so(tmp_path):
    """A file written before the lod_bound element is still read whole; lazily it is one line."""
    tree = build_hierarchy(_scene(200))
    n = tree.level_size(0)
    path = tmp_path / "old.lod.ply"
    ply_write.write_elements(path, [
        ("vertex", ply_write.scene_to_vertices(tree.nodes.subset(slice(0, n)), normals=False)),
        ("lod_node", ply_write.scene_to_vertices(tree.nodes.subset(slice(n, None)), normals=False))],
        comments=("written by splatgl lod", "lod branching 4"))
    assert np.array_equal(read_lod(path).radius, tree.radius)
    with pytest.raises(SplatglError, match="no 'lod_bound' element .*build it again with "
                                           "'splatgl lod'"):
        LazyLod(path)
