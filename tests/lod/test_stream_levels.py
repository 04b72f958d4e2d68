"""Streamed SOG and LCC streamed under a memory budget (issue 41 items 3 and 4):
splatgl.lod.level_cut (a level per chunk by screen error), splatgl.lod.stream_levels (headless
frames, exact for their choice) and splatgl.lod.stream_levels_view (the viewer's scene)."""

from __future__ import annotations

import threading

import numpy as np
import pytest

from helpers import random_scene
from lcc_files import write_lcc
from splatgl.cameras.camera import Camera
from splatgl.cameras.camera_files import save_camera
from splatgl.cameras.poses import look_at
from splatgl.cli import main
from splatgl.errors import SplatglError
from splatgl.formats import lcc, streamed_sog
from splatgl.imagefiles.images import read_image
from splatgl.lod.budget import StreamPlan
from splatgl.lod.level_cut import NOT_DRAWN, ChunkTable, choose_levels, level_errors
from splatgl.lod.selection import LodSettings
from splatgl.lod.stream_levels import ChunkedFrames
from splatgl.lod.stream_levels_view import ChunkedScene
from splatgl.scene.settings import EarlyStop, RenderSettings
from splatgl.scene.splats import Scene

SETTINGS = RenderSettings(near=0.01, early_stop=EarlyStop.OFF)
BUDGET = 40 << 10   # smaller than a level: chunks are evicted between frames


def cache_plan(cache: int, cap: int | None = None, per_splat: int = 100) -> StreamPlan:
    """A stream plan of ``cache`` bytes of chunks and a frame of at most ``cap`` splats (None:
    not capped), nothing else held (a tiny scene under budgets smaller than it)."""
    frame = (1 << 40) if cap is None else cap * per_splat
    return StreamPlan(budget=cache + frame, held=0, reserve=0, cache=cache, frame=frame,
                      per_splat=per_splat)


def _scene(n: int = 1200) -> Scene:
    return random_scene(n, 3, 0, wild_colors=0.0, log_scale=(-4.0, 0.5))


def _chunked(tmp_path, kind: str):
    """A small Streamed SOG (``splatgl lod scene.ply -o out/lod-meta.json``) or LCC (the white paper's layout) with an
    environment (LCC) and several chunks; its structure."""
    scene = _scene()
    if kind == "lcc":
        dc = np.clip(scene.sh[:, :1], -0.45 / 0.2821, 0.45 / 0.2821)
        scene = Scene(scene.means, scene.quats, scene.log_scales, scene.opacity_logits, dc)
        path = write_lcc(tmp_path, [scene, scene.subset(np.arange(0, 1200, 4))], cells=5,
                         environment=scene.subset(np.arange(20)))
        return path, lcc.read_structure(path)
    from splatgl.formats import ply_write

    ply_write.write(tmp_path / "scene.ply", scene)   # as a user writes one: 'splatgl lod'
    path = tmp_path / "out" / "lod-meta.json"
    path.parent.mkdir()
    assert main(["lod", str(tmp_path / "scene.ply"), "-o", str(path), "--chunk-splats", "256",
                 "--branching", "4"]) == 0
    return path, streamed_sog.read_structure(path)


def _camera(z: float, x: float = 0.0) -> Camera:
    return Camera.from_fov(96, 64, 50.0, look_at(np.array([x, 0.0, z]), np.zeros(3)))


def _anchored(scene: Scene, anchor) -> Scene:
    scene.__dict__["anchor"] = np.asarray(anchor, np.float64)
    return scene


@pytest.mark.parametrize("kind", ["streamed-sog", "lcc"])
@pytest.mark.parametrize("level", [0, 1])
def test_streamed_level_is_the_level_read_whole(tmp_path, gl_renderer, kind, level):
    """--lod-level N under a budget smaller than the level: each frame is the whole level's image
    (with its environment), the same anchor and near plane; chunks evicted between frames."""
    path, structure = _chunked(tmp_path, kind)
    cams = [_camera(4.0), _camera(3.0, 1.0)]
    with ChunkedFrames(path, SETTINGS, LodSettings(), BUDGET, level=level,
                       plan=cache_plan(BUDGET)) as frames:
        got = [out.rgba for out in map(frames.render_view, cams)]
        stats = frames.resident.stats
        whole = _anchored(structure.load(level), frames.framing.anchor)
        assert stats.peak_bytes <= BUDGET and (stats.evicted > 0) == (level == 0)  # 1 fits
        assert frames.last_cut_nodes == whole.count
        assert f"--lod-level {level}" in frames.summary()
    for cam, image in zip(cams, got):
        assert np.array_equal(gl_renderer.render(whole, cam, SETTINGS), image)


def test_level_errors_grow_with_coarser_levels():
    lo, hi = np.zeros((2, 3)), np.array([[2.0, 2.0, 2.0], [4.0, 4.0, 0.0]])  # the second flat
    err = level_errors(lo, hi, np.array([[800, 100, 0], [0, 50, 60]]))
    assert err[0, 0] == 0.0 and 0 < err[0, 1] < np.inf and err[0, 2] == np.inf
    assert err[1, 0] == np.inf and err[1, 1] == 0.0   # its finest level holding splats
    assert err[1, 2] >= err[1, 1]                     # never below a finer level's
    sphere = np.cbrt(3 * 8.0 / (4 * np.pi * 100))     # volume 8 shared by 100 splats
    assert err[0, 1] == pytest.approx(sphere)


@pytest.mark.parametrize("kind", ["streamed-sog", "lcc"])
def test_levels_by_screen_error_and_budget(tmp_path, gl_renderer, kind):
    """Far views draw coarser levels than near ones; a budget coarsens until the splats fit;
    chunks out of view are not drawn; the frame is the image of the chosen chunks read whole."""
    path, structure = _chunked(tmp_path, kind)
    with ChunkedFrames(path, SETTINGS, LodSettings(threshold_px=1.0), BUDGET,
                       plan=cache_plan(BUDGET)) as frames:
        table = frames.stream.table
        near = choose_levels(table, frames.stream.view_camera(_camera(1.5), SETTINGS),
                             LodSettings(threshold_px=1.0))
        far = choose_levels(table, _camera(4000.0), LodSettings(threshold_px=1.0))
        coarsest = table.levels - 1 - np.argmax((table.counts > 0)[:, ::-1], 1)
        assert np.array_equal(far, coarsest) and (near == 0).any()   # far: each chunk's coarsest
        assert table.splats(far) < table.splats(near)
        budget = choose_levels(table, _camera(1.5), LodSettings(threshold_px=1.0, budget=700))
        assert table.splats(budget) <= 700 and (budget >= 0).all()
        aside = choose_levels(table, Camera.from_fov(96, 64, 20.0, look_at(
            np.array([20.0, 0.0, 0.0]), np.array([60.0, 0.0, 0.0]))))
        assert (aside == NOT_DRAWN).all()   # looking away: nothing in view
        cam = _camera(2.5, 0.5)
        image = frames.render_view(cam).rgba
        levels = frames.stream.choose(frames.stream.view_camera(cam, SETTINGS))
        chosen = [structure.load(int(levels[c]), [c], environment=False)
                  for c in np.flatnonzero(levels >= 0)]
        if structure.has_environment:
            chosen.append(structure.load(0, [], environment=True))
        want = _anchored(streamed_sog.concatenate(chosen), frames.framing.anchor)
    assert np.array_equal(gl_renderer.render(want, cam, SETTINGS), image)


@pytest.mark.parametrize("kind", ["streamed-sog", "lcc"])
def test_viewer_draws_resident_levels_and_refines(tmp_path, kind):
    """The viewer's scene never waits: the pinned coarsest levels stand in, then (once the
    requested chunks are in) the view's exact choice, which exact_scene also gives."""
    path, structure = _chunked(tmp_path, kind)
    woke = []
    scene = ChunkedScene(path, LodSettings(threshold_px=1.0), 1 << 20,
                         on_change=lambda: woke.append(1), plan=cache_plan(1 << 20))
    try:
        counts = scene.stream.table.counts
        coarse = sum(int(row[row > 0][-1]) for row in counts) + (
            structure.load(0, [], environment=True).count if structure.has_environment else 0)
        cam = _camera(1.5)
        first = scene.scene_for(cam, SETTINGS)
        assert not scene.complete and first.count == coarse   # every chunk's coarsest level
        exact = scene.exact_scene(cam, SETTINGS)
        assert exact.count > coarse
        again = scene.scene_for(cam, SETTINGS)
        assert scene.complete and again is exact and woke and scene.generation >= len(woke)
        assert "refining" not in scene.summary()
    finally:
        scene.close()


def test_level_that_does_not_exist_is_one_line(tmp_path):
    path, _ = _chunked(tmp_path, "streamed-sog")
    with pytest.raises(SplatglError, match=r"--lod-level 7: .*lod-meta.json has \d levels"):
        ChunkedFrames(path, SETTINGS, LodSettings(), BUDGET, level=7, plan=cache_plan(BUDGET))


def test_budget_too_small_for_the_pinned_levels(tmp_path):
    path, _ = _chunked(tmp_path, "lcc")
    with pytest.raises(SplatglError, match="--memory .* too small"):
        ChunkedScene(path, LodSettings(), 2 << 10, plan=cache_plan(2 << 10))


def _view_args(tmp_path) -> list[str]:
    """An explicit camera and near plane: an LCC streamed frames its chunks' boxes, read whole
    its splats' 1-99 % box (a Streamed SOG splatgl wrote frames its recorded box both ways)."""
    save_camera(tmp_path / "cam.json", _camera(4.0, 0.5))
    return ["--camera", str(tmp_path / "cam.json"), "--near", "0.01", "--early-stop", "off",
            "--renderer", "quad"]


@pytest.mark.parametrize("kind", ["streamed-sog", "lcc"])
def test_render_memory_streams_the_level_the_whole_render_draws(tmp_path, kind, capsys):
    """``splatgl render SCENE --memory 1.5G --lod-level 0``: the image ``splatgl render SCENE``
    draws from the finest level read whole (to float32 rounding: the anchors differ); without
    --lod-level the levels by screen error.  (Budgets smaller than a level: the tests above.)"""
    path, structure = _chunked(tmp_path, kind)
    view = _view_args(tmp_path)
    assert main(["render", str(path), "-o", str(tmp_path / "whole.png"), *view]) == 0
    assert main(["render", str(path), "-o", str(tmp_path / "s.png"), "--memory", "1.5G",
                 "--lod-level", "0", "--timings", *view]) == 0
    out = capsys.readouterr().out
    assert "streamed under 1.5 GiB" in out and "loaded" in out and "--lod-level 0" in out
    a, b = read_image(tmp_path / "whole.png"), read_image(tmp_path / "s.png")
    assert a.max() > 0.2 and np.abs(a - b).max() <= 1.5 / 255, np.abs(a - b).max() * 255
    assert main(["render", str(path), "-o", str(tmp_path / "far.png"), "--memory", "1.5G",
                 "--lod-threshold", "1", "--timings", *view]) == 0
    assert "cut_nodes" in capsys.readouterr().out


def test_level_options_refused_in_one_line(tmp_path, capsys):
    path, _ = _chunked(tmp_path, "lcc")
    out = ["-o", str(tmp_path / "x.png")]
    cases = [
        (["--memory", "1M", "--lod-level", "2"], "--lod-level 2: ", "has 2 levels (0-1"),
        (["--lod-level", "1"], "--lod-level 1 draws a level", "add --memory SIZE"),
        (["--memory", "1M", "--lod-level", "1", "--lod-budget", "5"], "not with --lod-threshold",
         "--lod-level draws every chunk"),
        (["--memory", "1M", "--lod-blend", "2"], "--lod-blend: ", "drop --lod-blend"),
        (["--lod-budget", "5"], "add --memory SIZE", "choose a Streamed SOG's or LCC's levels"),
    ]
    for args, *expected in cases:
        assert main(["render", str(path), *out, *args]) == 2
        err = capsys.readouterr().err.strip()
        assert err.count("\n") == 0 and all(e in err for e in expected), err
    scene = tmp_path / "s.ply"
    from splatgl.formats import ply_write
    ply_write.write(scene, _scene(50))
    assert main(["render", str(scene), *out, "--memory", "1M", "--lod-level", "0"]) == 2
    assert "is not a Streamed SOG (lod-meta.json) or LCC" in capsys.readouterr().err
    assert not (tmp_path / "x.png").exists()


def test_bench_and_path_stream_a_chunked_scene(tmp_path, capsys):
    """``bench SCENE --memory`` and ``render --path --memory`` on a Streamed SOG: every frame
    streamed under the budget."""
    import json

    path, _ = _chunked(tmp_path, "streamed-sog")
    capsys.readouterr()   # what 'splatgl lod' said
    assert main(["bench", str(path), "--memory", "1.5G", "--quick", "--frames", "2",
                 "--width", "64", "--height", "48", "--json", "-"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["frames"] == 2 and report["resident_peak_bytes"] > 0
    assert report["chunks_loaded"] > 0 and report["bytes_read"] is None
    assert main(["render", str(path), "--memory", "1.5G", "--lod-level", "1", "--path",
                 "orbit:3", "-o", str(tmp_path / "f") + "/", "--width", "48", "--height",
                 "32"]) == 0
    assert "wrote 3 frames" in capsys.readouterr().out
    assert main(["bench", str(path), "--memory", "1.5G", "--lod-level", "9"]) == 2
    assert "--lod-level 9: " in capsys.readouterr().err


@pytest.mark.parametrize("kind", ["streamed-sog", "lcc"])
def test_frame_cap_coarsens_the_levels_and_says_so(tmp_path, gl_renderer, kind):
    """--memory bounds the frame too: a level asking more splats than the frame's cap is drawn
    with chunks coarsened (smallest screen error first) to the cap, said once; the image is
    those chunks' read whole."""
    path, structure = _chunked(tmp_path, kind)
    env = structure.load(0, [], environment=True).count if structure.has_environment else 0
    cam = _camera(2.5, 0.5)
    with ChunkedFrames(path, SETTINGS, LodSettings(), 1 << 20, level=0,
                       plan=cache_plan(1 << 20, cap=600 + env)) as frames:
        image = frames.render_view(cam).rgba
        assert frames.last_cut_nodes <= 600 + env
        assert "coarser than --lod-level 0 asked" in frames.capped
        assert "1 of 1 views capped" in frames.summary()
        levels = frames.stream.choose(frames.stream.view_camera(cam, SETTINGS))
        assert (levels > 0).any()
        chosen = [structure.load(int(levels[c]), [c], environment=False)
                  for c in np.flatnonzero(levels >= 0)]
        if env:
            chosen.append(structure.load(0, [], environment=True))
        want = _anchored(streamed_sog.concatenate(chosen), frames.framing.anchor)
    assert np.array_equal(gl_renderer.render(want, cam, SETTINGS), image)


@pytest.mark.slow
def test_eval_memory_scores_a_streamed_lcc(tmp_path, capsys):
    """``eval SCENE --memory --lod-level 0`` on an LCC: each view streamed (photographs: the
    whole level's renders with the stream's anchor, so the same images)."""
    import json

    from splatgl.api import Renderer
    from splatgl.datasets import colmap
    from splatgl.datasets.named_camera import NamedCamera
    from splatgl.imagefiles.images import write_image

    path, structure = _chunked(tmp_path, "lcc")
    root = tmp_path / "data"
    (root / "images").mkdir(parents=True)
    views = [NamedCamera(f"v{i}.png", _camera(4.0 + i, 0.3 * i)) for i in range(2)]
    with ChunkedFrames(path, RenderSettings(), LodSettings(), 1 << 20, 0,
                       plan=cache_plan(1 << 20)) as frames:
        whole = _anchored(structure.load(0), frames.framing.anchor)
    with Renderer() as gl:
        for view in views:
            rgba = gl.render(whole, view.camera, RenderSettings())
            write_image(root / "images" / view.name, np.concatenate(
                [np.clip(rgba[..., :3], 0, 1), np.ones_like(rgba[..., :1])], -1), 16)
    colmap.write_colmap(root / "sparse" / "0", views)
    assert main(["eval", str(path), "--dataset", str(root), "--memory", "1.5G", "--lod-level",
                 "0", "--json", str(tmp_path / "s.json")]) == 0
    assert "streaming: resident" in capsys.readouterr().out
    assert json.loads((tmp_path / "s.json").read_text())["mean"]["psnr"] > 60
    assert main(["eval", str(path), "--dataset", str(root), "--lod-level", "0"]) == 2
    assert "add --memory SIZE" in capsys.readouterr().err


@pytest.mark.window
def test_view_memory_window_refines_a_streamed_sog(xvfb_display, tmp_path):
    """One short window over a Streamed SOG: drawn from the pinned coarsest levels, again as
    chunks arrive until the view's choice is complete; the status panel shows resident memory;
    F12 waits for the chunks and writes the screenshot."""
    from splatgl.errors import ContextError
    from splatgl.viewer.app import Viewer, ViewerOptions
    from splatgl.viewer.screenshot import take_screenshot

    path, _ = _chunked(tmp_path, "streamed-sog")
    stream = ChunkedScene(path, LodSettings(), 1 << 20, plan=cache_plan(1 << 20))
    options = ViewerOptions(visible=True, screenshot_dir=tmp_path, render_args=(str(path),),
                            vsync=False, target_fps=0.0, stream=stream)
    try:
        try:
            v = Viewer(stream.framing, SETTINGS, _camera(3.0, 0.5), options=options)
        except ContextError as exc:
            pytest.skip(f"no OpenGL 4.3+ window context on Xvfb: {exc}")
        with v:
            assert v.step()
            for _ in range(100):
                if stream.complete:
                    break
                threading.Event().wait(0.02)
                v.step()
            assert stream.complete
            assert "resident" in v._status(v.camera()).message
            png, _ = take_screenshot(v)
            assert png.exists()
    finally:
        stream.close()


def test_streamed_sog_chunks_of_one_unit_decode_it_once(tmp_path, monkeypatch):
    """A Streamed SOG's chunks are row ranges of its SOG units: a frame's chunks of one unit
    decode that unit once (the loader keeps the last unit), not once a chunk."""
    path, structure = _chunked(tmp_path, "streamed-sog")
    level0 = {c.lods[0][0] for c in structure.chunks}
    assert len(structure.chunks) > len(level0)   # several chunks a unit
    decoded = []
    real = type(structure).unit
    monkeypatch.setattr(type(structure), "unit",
                        lambda self, file, *a: decoded.append(file) or real(self, file, *a))
    with ChunkedFrames(path, SETTINGS, LodSettings(), 1 << 20, level=0,
                       plan=cache_plan(1 << 20)) as frames:
        decoded.clear()   # the sample chunk's at open
        frames.render_view(_camera(4.0))
        assert frames.last_cut_nodes == structure.counts[0]
    assert sorted(decoded) == sorted(level0)


def test_viewer_view_fits_the_chunk_cache_and_completes(tmp_path):
    """The viewer keeps a view's chunks resident to complete it: a level larger than the
    chunks' share is coarsened to what fits (said in ``capped``), and the view completes."""
    path, structure = _chunked(tmp_path, "lcc")
    scene = ChunkedScene(path, LodSettings(), 64 << 10, level=0, plan=cache_plan(64 << 10))
    try:
        coarsest = sum(int(row[row > 0][-1]) for row in scene.stream.table.counts)
        assert coarsest < scene.stream.cap < structure.counts[0]
        cam = _camera(4.0)
        for _ in range(200):
            drawn = scene.scene_for(cam, SETTINGS)
            if scene.complete:
                break
            threading.Event().wait(0.01)
        assert scene.complete and "coarser than --lod-level 0 asked" in scene.capped
        assert drawn.count <= scene.stream.cap + 20   # and the 20 environment splats
        assert scene.resident.stats.peak_bytes <= 64 << 10
    finally:
        scene.close()
