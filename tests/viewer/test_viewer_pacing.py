"""The viewer's frame-time budget in a real glfw window under Xvfb (splatgl.viewer.pacing):
drafts while the camera moves, the exact frame at rest (what ``splatgl render`` writes), keys
held back while a refinement step draws, and no budget for ``--benchmark``."""

from __future__ import annotations

import numpy as np
import pytest

pytestmark = pytest.mark.window

W, H = 320, 240


@pytest.fixture(scope="module")
def scene():
    from helpers import IN_VIEW, random_scene

    return random_scene(20_000, seed=5, degree=1, **IN_VIEW)


def _viewer(scene, tmp_path, fps, vsync=False, kind="quad"):
    from splatgl.cameras.camera import Camera
    from splatgl.errors import ContextError
    from splatgl.scene.settings import RenderSettings
    from splatgl.viewer.app import Viewer, ViewerOptions

    options = ViewerOptions(screenshot_dir=tmp_path, vsync=vsync, target_fps=fps)
    try:
        return Viewer(scene, RenderSettings(background=(0.1, 0.2, 0.3)),
                      Camera.from_fov(W, H, 60.0, np.eye(4)), kind=kind, options=options)
    except ContextError as exc:
        pytest.skip(f"no OpenGL 4.3+ window context on Xvfb: {exc}")


def _move(v, n: int = 4) -> None:
    from dataclasses import replace

    for i in range(n):
        v.state = replace(v.state, yaw=v.state.yaw + 0.5)
        assert v.step(dt=0.0)


def _window(v) -> np.ndarray:
    """The window's pixels (the status panel hidden first: press I)."""
    v.ctx.screen.use()
    raw = v.ctx.screen.read(components=3)
    return np.frombuffer(raw, np.uint8).reshape(H, W, 3)[::-1].astype(np.int32)


@pytest.mark.parametrize("kind", ["quad", "cpu"])
def test_moving_drafts_then_exact_at_rest(xvfb_display, scene, tmp_path, kind):
    """With --renderer cpu the drafts are the quad path's too, and the rest ends at the CPU
    renderer's exact frame (what ``splatgl render --renderer cpu`` writes)."""
    if kind == "cpu":
        pytest.importorskip("numba", reason="the CPU renderer needs numba (the fast extra)")
    # A budget of 0.2 ms: every frame is over it, so moving frames are drafts.
    with _viewer(scene, tmp_path, 5000.0, kind=kind) as v:
        assert v.paced
        _move(v)
        assert not v.pacer.session.shown.level.exact
        assert v.last.quality.startswith("moving: scale")
        steps = 0
        while v.step(dt=0.0):
            steps += 1
            assert steps < 10
        assert v.pacer.exact and v.last.quality.startswith("exact")
        assert not v.step(dt=0.0)        # exact: nothing more to draw
        # the panel: the moving frames' rate, and the exact frame's cost no shorter than its
        # sort and draw (it said "sort 0.0", and a frame shorter than the draw)
        status = v._status(v.camera())
        assert status.moving and status.fps > 0.0 and status.sort > 0.0
        assert status.frame >= status.sort + status.draw > 0.0
        v.overlay.visible = False
        v.present()
        want = np.clip(v.renderer.render(scene, v.camera(), v.settings, kind)[..., :3], 0.0, 1.0)
        assert np.abs(_window(v) - np.round(want * 255)).max() <= 1
        got = v.pacer.session.levels.read(v.pacer.session.shown)
        assert np.array_equal(got, v.renderer.render(scene, v.camera(), v.settings, kind))


def test_keys_during_a_refinement_act_after_it(xvfb_display, scene, tmp_path, monkeypatch):
    import glfw

    from splatgl.imagefiles.images import read_image
    from splatgl.viewer import pacing

    with _viewer(scene, tmp_path, 5000.0) as v:
        _move(v)
        pressed = []

        def poll():   # a person presses F12 while the refinement draws
            if not pressed:
                pressed.append(True)
                v.on_key(glfw.KEY_F12, glfw.PRESS, 0)
                assert not list(tmp_path.glob("*.png")), "the screenshot ran in the middle of a draw"

        monkeypatch.setattr(pacing.glfw, "poll_events", poll)
        assert not v.step(dt=0.0)        # the step was abandoned for the key
        assert pressed and v.pacer.session.status == "refining"
        shots = list(tmp_path.glob("*.png"))
        assert len(shots) == 1           # the key acted once the draw was left
        want = np.clip(v.renderer.render(scene, v.camera(), v.settings)[..., :3], 0.0, 1.0)
        assert np.abs(read_image(shots[0]) - want).max() <= 0.5 / 255 + 1e-6


def test_no_budget_draws_every_frame_exact(xvfb_display, scene, tmp_path):
    with _viewer(scene, tmp_path, 0.0) as v:
        assert not v.paced
        _move(v, 2)
        assert v.pacer.session is None and v.last.quality == ""


def test_a_slow_present_comes_off_the_draws_budget(xvfb_display, scene, tmp_path, monkeypatch):
    """Moving frames of a window whose present takes 30 ms: the draw's budget drops by at least
    that, so whole frames (draw and present) aim at the period; refinement steps at rest do
    not count."""
    import time

    with _viewer(scene, tmp_path, 10.0) as v:
        draw = v.display.draw

        def slow_draw(*args):
            draw(*args)
            time.sleep(0.03)

        monkeypatch.setattr(v.display, "draw", slow_draw)
        _move(v, 5)
        session = v.pacer.session
        assert session.period == pytest.approx(0.1)
        assert session.budget.budget <= 0.1 - 0.03
        noted = list(session._overheads)
        assert len(noted) == 5 and min(noted) >= 0.03
        while v.step(dt=0.0):            # rest: refinement steps, not moving frames
            pass
        assert session._overheads == noted


def test_the_benchmark_reports_the_frames_median_and_10th_percentile(xvfb_display, scene, tmp_path):
    with _viewer(scene, tmp_path, 10.0) as v:
        v.step()
        r = v.benchmark(6)
        assert 0.0 < r["fps_p10"] <= r["fps_median"]
        assert r["fps"] == pytest.approx(1.0 / r["frame"])


def test_a_swap_that_waits_for_the_display_does_not_shrink_the_draws_budget(xvfb_display, scene,
                                                                           tmp_path, monkeypatch):
    """With vsync a swap waits for the display's refresh: idle time, not the window's cost, so
    the draw keeps its budget (a 60 fps budget would otherwise shrink to what leaves the wait).
    A swap that works (a software copy, in the drawing thread) still counts, and without vsync
    the whole swap does."""
    import time

    from splatgl.viewer import app

    def busy(seconds):   # this thread's CPU time, what the swap counts as work: on a busy
        end = time.thread_time() + seconds     # machine a wall-clock spin got less of it
        while time.thread_time() < end:
            pass

    swap = app.glfw.swap_buffers
    # a 70 ms wait: counted as work it would leave at most 30 ms; the rest of a frame (present,
    # status panel, a busy machine's delays) has 40 ms of room below the bound
    monkeypatch.setattr(app.glfw, "swap_buffers", lambda w: (swap(w), time.sleep(0.07)))
    with _viewer(scene, tmp_path, 10.0, vsync=True) as v:
        _move(v, 1)
        v.pacer.lod.wait()               # the tree's background build competes for the CPU
        _move(v, 9)
        session = v.pacer.session
        assert np.median(session._overheads) < 0.04
        assert session.budget.budget > 0.1 - 0.04
        monkeypatch.setattr(app.glfw, "swap_buffers", lambda w: (swap(w), busy(0.04)))
        _move(v, 9)
        assert session.budget.budget <= 0.1 - 0.03
    monkeypatch.setattr(app.glfw, "swap_buffers", lambda w: (swap(w), time.sleep(0.04)))
    with _viewer(scene, tmp_path, 10.0, vsync=False) as v:
        _move(v, 5)
        assert v.pacer.session.budget.budget <= 0.1 - 0.03


def test_leaving_the_depth_or_difference_view_redraws_the_colour_view_at_once(xvfb_display, scene,
                                                                             tmp_path):
    """Ctrl+D, C or Tab back to the colour view under a budget: the window shows the colour
    render again (it kept the depth map or heat map until the camera moved)."""
    import glfw

    from splatgl.viewer.modes import ViewMode

    with _viewer(scene, tmp_path, 5000.0) as v:
        v.on_key(glfw.KEY_I, glfw.PRESS, 0)          # panel hidden: the picture alone
        _move(v, 1)
        while v.step(dt=0.0):
            pass
        want = np.round(np.clip(v.renderer.render(scene, v.camera(), v.settings)[..., :3],
                                0.0, 1.0) * 255)
        for there, back in (((glfw.KEY_D, glfw.MOD_CONTROL),) * 2,
                            ((glfw.KEY_C, 0),) * 2,
                            ((glfw.KEY_TAB, 0), (glfw.KEY_TAB, 0))):
            v.on_key(there[0], glfw.PRESS, there[1])
            assert v.view is not ViewMode.COLOR and v.step(dt=0.0)
            v.on_key(back[0], glfw.PRESS, back[1])
            if v.view is not ViewMode.COLOR:          # Tab: depth -> difference -> colour
                assert v.step(dt=0.0)
                v.on_key(back[0], glfw.PRESS, back[1])
            assert v.view is ViewMode.COLOR and v.step(dt=0.0)
            while v.step(dt=0.0):
                pass
            assert np.abs(_window(v) - want).max() <= 1


@pytest.mark.slow   # a window and a dozen redraws as the chunks arrive: 2-4 s here
def test_a_streamed_scene_moves_under_the_budget_and_rests_until_every_chunk_is_in(
        xvfb_display, tmp_path):
    """``view --memory``: the budget's drafts while moving (from the resident chunks), then at
    rest the view's cut drawn again as chunks arrive, the loop asleep in between (``awaiting``),
    until the frame is exact: the exact cut's image."""
    import threading

    from test_stream_session import _Gated, cache_plan, tiny_lod

    from splatgl.cameras.camera import Camera
    from splatgl.cameras.poses import look_at
    from splatgl.errors import ContextError
    from splatgl.lod.lazy import LazyLod
    from splatgl.lod.selection import LodSettings
    from splatgl.lod.stream import LazyChunks
    from splatgl.lod.stream_view import StreamedScene
    from splatgl.scene.settings import RenderSettings
    from splatgl.viewer.app import Viewer, ViewerOptions

    path = tiny_lod(tmp_path)
    lazy = LazyLod(path)
    chunks = _Gated(LazyChunks(lazy, 512))
    stream = StreamedScene(path, LodSettings(), 1 << 30, chunks=chunks, plan=cache_plan(1 << 20))
    chunks.gated = True
    settings = RenderSettings(near=0.01)
    camera = Camera.from_fov(W, H, 50.0, look_at(np.array([0.3, 0.0, 1.6]), np.zeros(3)))
    options = ViewerOptions(screenshot_dir=tmp_path, vsync=False, target_fps=5000.0, stream=stream)
    try:
        try:
            v = Viewer(stream.framing, settings, camera, options=options)
        except ContextError as exc:
            pytest.skip(f"no OpenGL 4.3+ window context on Xvfb: {exc}")
        with v:
            assert v.paced
            _move(v, 2)
            assert not v.pacer.session.shown.level.exact and v.last.quality.startswith("moving")
            while v.step(dt=0.0):   # the refinement's steps, short of chunks
                pass
            assert not v.pacer.exact and v.pacer.awaiting and v.pacer.refining
            assert not v.step(dt=0.0)   # nothing arrived: nothing drawn
            chunks.gate.set()
            for _ in range(400):
                v.step(dt=0.0)
                if v.pacer.exact:
                    break
                threading.Event().wait(0.01)
            assert v.pacer.exact and stream.complete and not v.pacer.awaiting
            got = v.pacer.session.levels.read(v.pacer.session.shown)
            want = v.renderer.render(stream.exact_scene(v.camera(), settings), v.camera(), settings)
            assert np.array_equal(got, want)
    finally:
        stream.close()
        lazy.close()
