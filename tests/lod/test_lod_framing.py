"""One framing of a ``.lod.ply``: the leaves' 1-99 % box its header records frames it whether it
is read whole (``load_scene``, ``read_lod``) or streamed under ``--memory`` (``framing_scene``),
so ``--memory`` does not move the default view (before, the streamed frames framed a coarse
level's box and the in-memory ones the leaves').  The same for a Streamed SOG ``splatgl lod``
writes: its manifest records the box (``splatglFramingBox``)."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest

from splatgl.cameras.framing import default_camera
from splatgl.cli import main
from splatgl.formats import load_scene
from splatgl.formats.metadata import box_comment, framing_box, header_box
from splatgl.imagefiles.images import read_image
from splatgl.lod.io import leaf_box
from splatgl.lod.lazy import LazyLod
from splatgl.lod.stream_frames import framing_scene
from helpers import stream_lod_file

SIZE = ["--width", "96", "--height", "64"]


def _framing(path):
    with LazyLod(path) as lazy:
        return framing_scene(lazy)


def test_the_header_records_the_leaves_box(tmp_path):
    path = stream_lod_file(tmp_path)
    source = load_scene(tmp_path / "s.ply")
    lo, hi = framing_box(path)
    want_lo, want_hi = leaf_box(source.means)
    assert np.array_equal(lo, want_lo) and np.array_equal(hi, want_hi)
    assert framing_box(tmp_path / "s.ply") is None   # a plain PLY records none
    # the source scene's own box: its float32 percentiles, the same up to their rounding
    np.testing.assert_allclose(source.robust_bounds, (lo, hi), rtol=0, atol=1e-6)


def test_read_whole_and_streamed_frame_the_same_default_view(tmp_path):
    path = stream_lod_file(tmp_path)
    whole, streamed = load_scene(path), _framing(path)
    for a, b in zip(whole.robust_bounds, streamed.robust_bounds):
        assert np.array_equal(a, b)
    cams = [default_camera(s, 96, 64) for s in (whole, streamed)]
    for field in dataclasses.fields(cams[0]):
        assert np.array_equal(getattr(cams[0], field.name), getattr(cams[1], field.name))


def test_a_file_without_the_box_is_framed_by_its_proxy(tmp_path):
    """Files written before the box: the stream frames a coarse level (as before), the reader
    the leaves' own percentiles."""
    path = stream_lod_file(tmp_path)
    data = path.read_bytes()
    line = ("comment " + box_comment(*framing_box(path))).encode()
    assert data.count(line) == 1
    path.write_bytes(data.replace(line, b"comment " + b"x" * (len(line) - 8)))  # same offsets
    assert framing_box(path) is None
    whole, streamed = load_scene(path), _framing(path)
    source = load_scene(tmp_path / "s.ply")
    for a, b in zip(whole.robust_bounds, source.robust_bounds):
        assert np.array_equal(a, b)
    assert not np.array_equal(streamed.robust_bounds[0], whole.robust_bounds[0])


@pytest.mark.parametrize("values", [
    "0 0 0 1 1",            # five numbers
    "0 0 0 1 nan 1",        # not finite
    "0 2 0 1 1 1",          # lo above hi
    "0 0 0 1 1 x",          # not a number
])
def test_a_malformed_box_is_ignored(values):
    head = f"ply\nformat binary_little_endian 1.0\ncomment lod box {values}\nend_header\n"
    assert header_box(head.encode()) is None


def test_box_comment_reads_back_exactly():
    lo, hi = np.array([-1 / 3, 0.1, -2e-9]), np.array([1 / 7, 0.2, 3.0])
    head = f"ply\ncomment {box_comment(lo, hi)}\nend_header\n".encode()
    got = header_box(head)
    assert np.array_equal(got[0], lo) and np.array_equal(got[1], hi)


def test_render_default_view_is_the_same_with_and_without_memory(tmp_path, capsys):
    """The CLI: ``render x.lod.ply`` and ``render x.lod.ply --memory`` with no camera given
    write the same image (a budget's cut, the quad path both ways)."""
    path = stream_lod_file(tmp_path)
    common = [str(path), "--lod-budget", "400", "--renderer", "quad", *SIZE]
    assert main(["render", *common, "-o", str(tmp_path / "a.exr")]) == 0
    assert main(["render", *common, "-o", str(tmp_path / "b.exr"), "--memory", "3G"]) == 0
    capsys.readouterr()
    a, b = read_image(tmp_path / "a.exr"), read_image(tmp_path / "b.exr")
    assert np.array_equal(a, b) and a[..., 3].max() > 0


def test_info_names_a_lod_files_levels(tmp_path, capsys):
    """``splatgl info x.lod.ply``: its levels, from the header."""
    path = stream_lod_file(tmp_path)   # 3000 leaves, branching 4
    assert main(["info", str(path)]) == 0
    assert ("levels:      7 of a tree with branching 4, splats per level 0: 3000, 1: 750, 2: 188"
            in capsys.readouterr().out)
    assert main(["info", str(tmp_path / "s.ply")]) == 0
    assert "levels:" not in capsys.readouterr().out


def test_path_orbit_is_the_same_with_and_without_memory(tmp_path, capsys):
    """``render --path orbit`` of a ``.lod.ply``: the orbit frames the recorded box both ways,
    so the frames read whole and streamed are the same images."""
    path = stream_lod_file(tmp_path)
    common = [str(path), "--path", "orbit:2", "--lod-budget", "400", "--renderer", "quad", *SIZE]
    assert main(["render", *common, "-o", str(tmp_path / "a%d.exr")]) == 0
    assert main(["render", *common, "-o", str(tmp_path / "b%d.exr"), "--memory", "3G"]) == 0
    capsys.readouterr()
    for i in range(2):
        a, b = read_image(tmp_path / f"a{i}.exr"), read_image(tmp_path / f"b{i}.exr")
        assert np.array_equal(a, b) and a[..., 3].max() > 0


def _streamed_sog(tmp_path):
    """``splatgl lod s.ply -o out/lod-meta.json``: a Streamed SOG of several chunks."""
    stream_lod_file(tmp_path)      # writes s.ply, the source
    out = tmp_path / "out" / "lod-meta.json"
    out.parent.mkdir()
    assert main(["lod", str(tmp_path / "s.ply"), "-o", str(out), "--chunk-splats", "512"]) == 0
    return out


def test_a_streamed_sog_splatgl_writes_is_framed_alike_read_whole_and_streamed(tmp_path, capsys):
    """The manifest records the leaves' box (``splatglFramingBox``, as a ``.lod.ply`` header
    does): ``render`` and ``render --memory --lod-level 0`` without a camera write the same
    image (before, the stream framed its chunks' box: other pixels, up to 0.76 apart)."""
    from splatgl.formats import streamed_sog
    from splatgl.formats.metadata import BOX_KEY
    from splatgl.lod.stream_levels import framing_at

    out = _streamed_sog(tmp_path)
    source = load_scene(tmp_path / "s.ply")
    structure = streamed_sog.read_structure(out)
    assert len(structure.chunks) > 2
    for got, want in zip(structure.box, leaf_box(source.means)):
        assert np.array_equal(got, want)
    whole, streamed = load_scene(out), framing_at(out)
    for a, b in zip(whole.robust_bounds, streamed.robust_bounds):
        assert np.array_equal(a, b)
    assert np.array_equal(whole.anchor, streamed.anchor)
    common = [str(out), "--renderer", "quad", *SIZE]
    assert main(["render", *common, "-o", str(tmp_path / "a.exr")]) == 0
    assert main(["render", *common, "-o", str(tmp_path / "b.exr"), "--memory", "3G",
                 "--lod-level", "0"]) == 0
    capsys.readouterr()
    a, b = read_image(tmp_path / "a.exr"), read_image(tmp_path / "b.exr")
    assert np.array_equal(a, b) and a[..., 3].max() > 0
    # a malformed box is ignored: the stream frames its chunks, the reader the splats
    meta = json.loads(out.read_text())
    meta[BOX_KEY] = [0, 0, 0, 1, "x", 1]
    out.write_text(json.dumps(meta))
    assert streamed_sog.read_structure(out).box is None and framing_box(out) is None
    np.testing.assert_allclose(load_scene(out).robust_bounds, whole.robust_bounds, atol=0.05)
    assert not np.array_equal(framing_at(out).robust_bounds[0], whole.robust_bounds[0])
