"""Streamed level-of-detail frames drawn by the CPU renderer (issue 41 item 3 with issue 40
item 4): ``--renderer cpu`` (and ``auto`` where it chooses cpu) for ``render``/``render --path``/
``eval``/``bench`` with ``--memory``, the cut the quad path would draw, the CPU renderer's own
bytes a splat in the memory plan."""

from __future__ import annotations

import numpy as np
import pytest

from splatgl.cameras.view import View
from splatgl.cli import main
from splatgl.imagefiles.images import read_image
from splatgl.lod.budget import (CPU_DRAW_RESERVE, CPU_RENDERER_BYTES, FRAME_CPU_BYTES,
                                FRAME_SH_BYTES, StreamPlan)
from splatgl.lod.frames import LodFrames
from splatgl.lod.io import read_lod
from splatgl.lod.lazy import LazyLod
from splatgl.lod.selection import LodSettings, blended_scene
from splatgl.lod.stream_frames import StreamFrames
from splatgl.lod.stream_levels import ChunkedStream
from splatgl.renderers import auto
from splatgl.renderers.cpu import CpuRenderer
from splatgl.scene.settings import EarlyStop, RendererKind, RenderSettings
from helpers import stream_camera, stream_lod_file

pytest.importorskip("numba")

SETTINGS = RenderSettings(near=0.01, early_stop=EarlyStop.OFF)
CPU = RendererKind.CPU


_lod, _camera = stream_lod_file, stream_camera   # the streaming tests' scene and views


def _small_plan(cache: int = 96 << 10) -> StreamPlan:
    """Chunks of at most ``cache`` bytes (smaller than the file: chunks are evicted), the frame
    not capped."""
    return StreamPlan(budget=cache + (1 << 40), held=0, reserve=0, cache=cache, frame=1 << 40,
                      per_splat=100)


@pytest.mark.parametrize("lod", [LodSettings(), LodSettings(threshold_px=2.0, band=1.0),
                                 LodSettings(budget=300)], ids=["blend", "hard", "budget"])
def test_cpu_streamed_frame_is_the_cpu_render_of_the_in_memory_cut(tmp_path, lod):
    """The CPU renderer's streamed frame is, bit for bit, the CPU renderer's image of the cut the
    in-memory level of detail draws (its nodes with the cut's opacity weights,
    :func:`blended_scene`), under a chunk budget smaller than the file."""
    path = _lod(tmp_path)
    tree = read_lod(path)
    with LazyLod(path) as lazy:
        tree.nodes.__dict__["anchor"] = lazy.anchor
    cams = [_camera(8.0), _camera(3.0, 0.5), _camera(6.0, -1.0)]
    with LodFrames(tree, SETTINGS, lod) as ref, \
            StreamFrames(path, SETTINGS, lod, 96 << 10, chunk_rows=64, framing=tree.nodes,
                         plan=_small_plan(), kind=CPU) as st:
        assert st.ctx is None               # no OpenGL context for the CPU renderer
        for cam in cams:
            ref.render_view(cam)
            rows, weights = ref.renderer.rows.last_cut
            cut = blended_scene(tree, rows, weights)
            cut.__dict__["anchor"] = tree.nodes.anchor
            expected = CpuRenderer(cut, SETTINGS).render(View.of(cam, SETTINGS, tree.nodes))
            got = st.render_view(cam)
            assert isinstance(st.renderer, CpuRenderer)
            assert st.last_cut_nodes == rows.size
            assert np.array_equal(got.rgba, expected.rgba)
        assert st.resident.stats.loaded > 0
        assert st.resident.stats.peak_bytes <= 96 << 10


def test_cpu_stream_plans_its_own_bytes_a_splat(tmp_path):
    """The memory plan of a CPU-drawn stream counts the CPU renderer's bytes a splat (and its
    own draw reserve), not the quad path's GPU storage and buffers: the frame's cap stays
    honest."""
    path = _lod(tmp_path)
    sh = FRAME_CPU_BYTES + FRAME_SH_BYTES * 4 + CPU_RENDERER_BYTES   # SH degree 1: 4 coeffs
    with StreamFrames(path, SETTINGS, LodSettings(), 1536 << 20, kind=CPU) as st:
        assert (st.plan.per_splat, st.plan.reserve) == (sh, CPU_DRAW_RESERVE)
        assert st.plan.cap == st.plan.frame // sh
    with StreamFrames(path, SETTINGS, LodSettings(), 1536 << 20) as quad:
        assert quad.plan.per_splat != sh


def test_chunked_stream_plans_the_cpu_renderers_bytes(tmp_path):
    """A Streamed SOG's or LCC's plan with the CPU renderer drawing: the same bytes a splat."""
    path = _lod(tmp_path)
    out = tmp_path / "sog" / "lod-meta.json"
    out.parent.mkdir()
    assert main(["lod", str(tmp_path / "s.ply"), "-o", str(out)]) == 0
    stream = ChunkedStream(out, LodSettings(), 1536 << 20, cpu=True)
    try:
        assert stream.plan.reserve == CPU_DRAW_RESERVE
        assert stream.plan.per_splat == FRAME_CPU_BYTES + FRAME_SH_BYTES * 4 + CPU_RENDERER_BYTES
    finally:
        stream.close()
    assert path.exists()


def test_render_memory_with_the_cpu_renderer(tmp_path, capsys):
    """``render --memory --renderer cpu``: the CPU renderer draws (``--timings`` names it, no
    GL renderer), the image is not the quad path's; a path's frames too."""
    path = _lod(tmp_path)
    size = ["--width", "96", "--height", "64"]
    assert main(["render", str(path), "-o", str(tmp_path / "a.png"), "--memory", "1.5G",
                 "--renderer", "cpu", "--timings", *size]) == 0
    out = capsys.readouterr().out
    assert "cpu, level of detail streamed under 1.5 GiB" in out
    assert "GL renderer: none (the CPU renderer" in out and "streaming resident" in out
    assert main(["render", str(path), "-o", str(tmp_path / "q.png"), "--memory", "1.5G",
                 "--renderer", "quad", *size]) == 0
    a, q = read_image(tmp_path / "a.png"), read_image(tmp_path / "q.png")
    assert a.shape == q.shape and a.any() and not np.array_equal(a, q)
    assert main(["render", str(path), "-o", str(tmp_path / "p" / "%02d.png"), "--path",
                 "orbit:2", "--memory", "1.5G", "--renderer", "cpu", "--timings", *size]) == 0
    out = capsys.readouterr().out
    assert "cpu, level of detail streamed under 1.5 GiB" in out and "wrote 2 frames" in out
    assert "GL renderer: none (the CPU renderer" in out


def test_render_memory_auto_takes_the_cpu_renderer_where_auto_chooses_it(tmp_path, capsys,
                                                                         monkeypatch):
    """``--renderer auto`` (the default) on a streamed frame resolves as an in-memory render
    does: where :func:`splatgl.renderers.auto.choose` says cpu, the CPU renderer draws, and
    ``--timings`` says the choice."""
    path = _lod(tmp_path)
    monkeypatch.setattr(auto, "choose", lambda **kw: auto.Choice(CPU, "test: software"))
    assert main(["render", str(path), "-o", str(tmp_path / "a.png"), "--memory", "1.5G",
                 "--width", "96", "--height", "64", "--timings"]) == 0
    out = capsys.readouterr().out
    assert "renderer auto -> cpu (test: software)" in out
    assert "cpu, level of detail streamed" in out
    a = read_image(tmp_path / "a.png")
    assert main(["render", str(path), "-o", str(tmp_path / "b.png"), "--memory", "1.5G",
                 "--width", "96", "--height", "64", "--renderer", "cpu"]) == 0
    assert np.array_equal(a, read_image(tmp_path / "b.png"))


def test_render_memory_auto_pinned_is_the_quad_path(tmp_path, capsys):
    """The suite pins auto to quad: a streamed frame's auto says so and draws with quad."""
    path = _lod(tmp_path)
    assert main(["render", str(path), "-o", str(tmp_path / "a.png"), "--memory", "1.5G",
                 "--width", "96", "--height", "64", "--timings"]) == 0
    out = capsys.readouterr().out
    assert "renderer auto -> quad (SPLATGL_RENDERER_AUTO=quad)" in out
    assert "quad, level of detail streamed" in out


def test_bench_memory_names_its_renderer(tmp_path, capsys):
    """``bench SCENE.lod.ply --memory``: the CPU renderer where auto takes it, said."""
    from splatgl.measure.bench.stream_bench import run_stream

    path = _lod(tmp_path)
    r = run_stream(path, 1536 << 20, 96, 64, 2, SETTINGS, kind=CPU)
    assert r["renderer"] == "cpu"
    r = run_stream(path, 1536 << 20, 96, 64, 2, SETTINGS)
    assert (r["renderer"], r["renderer_choice"]) == ("quad", "renderer auto -> quad "
                                                              "(SPLATGL_RENDERER_AUTO=quad)")


def test_eval_memory_with_the_cpu_renderer(tmp_path, capsys):
    """``eval --memory --renderer cpu``: the views drawn by the CPU renderer from the stream
    (photographs: its in-memory images of the same cuts, so identical)."""
    from splatgl.datasets import colmap
    from splatgl.datasets.named_camera import NamedCamera
    from splatgl.imagefiles.images import write_image

    path = _lod(tmp_path)
    root = tmp_path / "data"
    (root / "images").mkdir(parents=True)
    views = [NamedCamera(f"v{i}.png", _camera(5.0 + i, 0.3 * i)) for i in range(2)]
    with StreamFrames(path, RenderSettings(), LodSettings(), 1536 << 20, kind=CPU) as st:
        for view in views:
            rgba = st.render_view(view.camera).rgba
            write_image(root / "images" / view.name, np.concatenate(
                [np.clip(rgba[..., :3], 0, 1), np.ones_like(rgba[..., :1])], -1), 16)
    colmap.write_colmap(root / "sparse" / "0", views)
    assert main(["eval", str(path), "--dataset", str(root), "--memory", "1.5G", "--renderer",
                 "cpu", "--json", str(tmp_path / "s.json")]) == 0
    assert "streaming: resident" in capsys.readouterr().out
    import json
    assert json.loads((tmp_path / "s.json").read_text())["mean"]["psnr"] > 80


def test_streamed_sog_with_the_cpu_renderer(tmp_path, capsys):
    """A Streamed SOG streamed with ``--renderer cpu``: drawn without OpenGL, said in --timings."""
    _lod(tmp_path)
    out = tmp_path / "sog" / "lod-meta.json"
    out.parent.mkdir()
    assert main(["lod", str(tmp_path / "s.ply"), "-o", str(out)]) == 0
    capsys.readouterr()
    assert main(["render", str(out), "-o", str(tmp_path / "a.png"), "--memory", "1.5G",
                 "--renderer", "cpu", "--width", "96", "--height", "64", "--timings"]) == 0
    text = capsys.readouterr().out
    assert "cpu, level of detail streamed" in text and "GL renderer: none (the CPU renderer" in text
    assert read_image(tmp_path / "a.png").any()
