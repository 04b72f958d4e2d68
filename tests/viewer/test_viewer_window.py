"""The viewer in a real glfw window under Xvfb, driven from Python.

Input is injected through the same ``Viewer.on_*`` handlers the glfw callbacks call, and
``Viewer.step()`` runs one loop iteration.  Skips where Xvfb is missing or glfw cannot open a
window on it.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time

import numpy as np
import pytest

pytestmark = pytest.mark.window

W, H = 320, 240
@pytest.fixture(scope="module")
def demo():
    from splatgl.commands._common import demo_scene_path
    from splatgl.formats import load_scene

    path = demo_scene_path()
    return path, load_scene(path)


@pytest.fixture
def viewer(xvfb_display, demo, tmp_path):
    from splatgl.errors import ContextError
    from splatgl.api import default_camera
    from splatgl.scene.settings import RenderSettings
    from splatgl.viewer.app import Viewer, ViewerOptions

    path, scene = demo
    # No frame-time budget: these tests count frames, and with one a cold shader cache (a fresh
    # machine; MESA_SHADER_CACHE_DISABLE=true) made the first frame slow, the next one a draft
    # and the one after a refinement step.  tests/viewer/test_viewer_pacing.py covers the budget.
    options = ViewerOptions(visible=True, screenshot_dir=tmp_path, render_args=(str(path),), vsync=False,
                            target_fps=0.0)
    try:
        v = Viewer(scene, RenderSettings(background=(0.1, 0.2, 0.3)), default_camera(scene, W, H),
                   options=options)
    except ContextError as exc:
        pytest.skip(f"no OpenGL 4.3+ window context on Xvfb: {exc}")
    yield v
    v.close()


def _window_pixels(v) -> np.ndarray:
    """(H, W, 3) uint8 of the window's front buffer contents, row 0 at the top."""
    w, h = v.size
    v.ctx.screen.use()
    raw = v.ctx.screen.read(components=3)  # after swap: the back buffer holds the same frame
    return np.frombuffer(raw, np.uint8).reshape(h, w, 3)[::-1]


def test_drag_key_screenshot_matches_headless_render(viewer, demo, tmp_path):
    import glfw

    from splatgl.imagefiles.images import read_image

    v = viewer
    assert v.step() and v.frames_rendered == 1
    v.on_mouse_button(glfw.MOUSE_BUTTON_LEFT, glfw.PRESS, 0)
    for x in range(100, 160, 10):
        v.on_cursor(x, 120 + (x - 100) // 4)
    v.on_mouse_button(glfw.MOUSE_BUTTON_LEFT, glfw.RELEASE, 0)
    v.on_key(glfw.KEY_RIGHT_BRACKET, glfw.PRESS, 0)   # wider field of view
    v.on_key(glfw.KEY_W, glfw.PRESS, 0)               # hold W: fly forward
    assert v.step(dt=0.05)
    v.on_key(glfw.KEY_W, glfw.RELEASE, 0)
    v.on_key(glfw.KEY_I, glfw.PRESS, 0)               # hide the status panel
    v.step()
    assert v.frames_rendered == 2
    assert v.state != v.home

    png, js = v.screenshot()
    assert json.loads(js.read_text())["width"] == W
    shown = _window_pixels(v).astype(np.int32)  # before the confirmation is drawn
    # With the panel hidden, the window confirms the screenshot too (the message alone), read
    # before the headless render below, which can outlast the message's few seconds when busy.
    v.step()
    assert v.overlay.lines == [f"saved {png.name} + {js.name} (exact render)"]
    assert not v.overlay.full and v.overlay.image is not None
    ref = tmp_path / "headless.png"
    r = subprocess.run([sys.executable, "-m", "splatgl", "render", str(demo[0]), "--camera", str(js),
                        "--background", "0.1,0.2,0.3", "-o", str(ref)],
                       capture_output=True, text=True, timeout=60)
    assert r.returncode == 0, r.stderr
    got, want = read_image(png), read_image(ref)
    assert got.shape == want.shape == (H, W, 3)
    assert np.abs(got - want).max() <= 1.0 / 255.0 + 1e-6
    assert want.std() > 0.01  # the scene is in view, not just background

    # What the window shows is that image: same rows (no y flip), within one 8-bit step.
    assert np.abs(shown - np.round(got * 255).astype(np.int32)).max() <= 1


def test_unchanged_camera_renders_no_new_frame(viewer):
    v = viewer
    v.step()
    frames, presents = v.frames_rendered, v.presents
    for _ in range(5):
        assert not v.step()
    assert v.frames_rendered == frames
    assert v.presents <= presents + 1  # at most one overlay refresh, never a render
    v.on_scroll(0.0, 1.0)
    assert v.step() and v.frames_rendered == frames + 1


def test_resize_to_zero_and_back(viewer):
    import glfw

    v = viewer
    v.step()
    frames = v.frames_rendered
    v.on_resize(0, 0)                 # what a minimised window reports on some platforms
    v.on_mouse_button(glfw.MOUSE_BUTTON_RIGHT, glfw.PRESS, 0)
    v.on_cursor(10, 10)
    v.on_cursor(30, 25)               # pan while minimised: state changes, nothing is drawn
    v.on_mouse_button(glfw.MOUSE_BUTTON_RIGHT, glfw.RELEASE, 0)
    assert not v.step() and not v.step()
    assert v.frames_rendered == frames
    glfw.iconify_window(v.window)
    glfw.poll_events()
    v.step()
    glfw.restore_window(v.window)
    glfw.set_window_size(v.window, 200, 150)
    hang_guard = time.monotonic() + 120.0  # the server answers at once; this only ends a hang
    while v.size != (200, 150) and time.monotonic() < hang_guard:
        glfw.wait_events_timeout(1.0)  # returns as soon as the resize event arrives
    assert v.size == (200, 150)
    assert v.step()
    assert v.last.texture.size == (200, 150)


def test_views_keys_and_closing(viewer, monkeypatch):
    import glfw

    from splatgl.viewer import app

    from splatgl.scene.settings import Precision, RendererKind
    from splatgl.viewer.modes import ViewMode

    v = viewer
    v.step()
    v.on_key(glfw.KEY_D, glfw.PRESS, glfw.MOD_CONTROL)
    assert v.view is ViewMode.DEPTH and v.step() and v.last.image is not None
    # the depth view is exact too, and names its splats once ("splats 1,604 splats")
    assert "exact (as splatgl render)" in v.overlay.lines
    assert v._status(v.camera()).splats == "splats 1,604 drawn / 1,604"
    v.on_key(glfw.KEY_C, glfw.PRESS, 0)
    assert v.view is ViewMode.DIFFERENCE and v.step()
    assert "max |quad - tile|" in v.last.note
    v.on_key(glfw.KEY_C, glfw.PRESS, 0)
    v.on_key(glfw.KEY_T, glfw.PRESS, 0)
    assert v.kind is RendererKind.TILE and v.step() and "tile keys" in v.last.splats
    v.on_key(glfw.KEY_T, glfw.PRESS, 0)              # T steps quad -> tile -> cpu -> quad
    assert v.kind is RendererKind.CPU and v.step() and "tile entries" in v.last.splats
    v.on_key(glfw.KEY_T, glfw.PRESS, 0)
    assert v.kind is RendererKind.QUAD
    v.on_key(glfw.KEY_P, glfw.PRESS, 0)
    assert v.settings.precision is Precision.RGBA16F and v.step()
    v.on_key(glfw.KEY_1, glfw.PRESS, 0)
    assert v.settings.sh_degree == 1 and v.step()
    v.on_key(glfw.KEY_H, glfw.PRESS, 0)
    v.step()
    assert v.overlay.show_keys and v.overlay.image.shape[0] > 200
    assert any(line.startswith("U\tcycle the up direction") for line in v.overlay.lines)
    frames = v.frames_rendered
    v.on_key(glfw.KEY_U, glfw.PRESS, 0)            # up -y (the demo's) -> +z -> -z -> +y
    assert v.state.up == v.home.up == (0.0, 0.0, 1.0) and v.message.startswith("up +z")
    assert v.step() and v.frames_rendered == frames + 1
    for up in ((0.0, 0.0, -1.0), (0.0, 1.0, 0.0), (0.0, -1.0, 0.0)):
        v.on_key(glfw.KEY_U, glfw.PRESS, 0)
        assert v.state.up == up
    # Esc while the loop waits for events: it quits without drawing another frame
    steps = []
    monkeypatch.setattr(app.glfw, "wait_events_timeout",
                        lambda t: v.on_key(glfw.KEY_ESCAPE, glfw.PRESS, 0))
    monkeypatch.setattr(v, "step", lambda *a: steps.append(a))
    v.run()
    assert v.should_close() and steps == []
    assert v.ctx.error == "GL_NO_ERROR"


def test_training_cameras_step(xvfb_display, demo, tmp_path):
    import glfw

    from splatgl.cameras.poses import orbit
    from splatgl.cameras.camera_files import load_cameras
    from splatgl.scene.settings import RenderSettings
    from splatgl.viewer.app import Viewer, ViewerOptions

    path, scene = demo
    centre = 0.5 * np.add(*scene.robust_bounds)
    entries = []
    for az in (0.0, 120.0, 240.0):
        w2c = orbit(centre, 3 * scene.robust_radius, az, 10.0)
        c2w = np.linalg.inv(w2c)
        entries.append({"id": len(entries), "img_name": f"{az}", "width": W, "height": H,
                        "position": c2w[:3, 3].tolist(), "rotation": c2w[:3, :3].tolist(),
                        "fx": 300.0, "fy": 300.0})
    cams_path = tmp_path / "cameras.json"
    cams_path.write_text(json.dumps(entries))
    cams = load_cameras(cams_path)
    with Viewer(scene, RenderSettings(), cams[0], cams, 0,
                options=ViewerOptions(screenshot_dir=tmp_path, vsync=False)) as v:
        v.on_key(glfw.KEY_N, glfw.PRESS, 0)
        assert v.camera_index == 1
        assert np.allclose(v.camera().world_to_camera, cams[1].world_to_camera, atol=1e-9)
        assert v.camera().fy == pytest.approx(300.0)
        v.on_key(glfw.KEY_PAGE_UP, glfw.PRESS, 0)
        v.on_key(glfw.KEY_N, glfw.PRESS, glfw.MOD_SHIFT)
        assert v.camera_index == 2  # 1 -> 0 -> 2 (wraps)
        assert v.step()
        v.on_key(glfw.KEY_R, glfw.PRESS, 0)
        assert np.allclose(v.camera().world_to_camera, cams[0].world_to_camera, atol=1e-9)


def test_bad_scene_exits_2_without_traceback(tmp_path):
    bad = tmp_path / "broken.ply"
    bad.write_bytes(b"ply\nformat binary_little_endian 1.0\nelement vertex 10\nend_header\n\x00")
    r = subprocess.run([sys.executable, "-m", "splatgl", "view", str(bad)], capture_output=True,
                       text=True, timeout=60, env={**os.environ, "DISPLAY": ""})
    assert r.returncode == 2
    assert "Traceback" not in r.stderr and "error" in r.stderr


def test_stereo_and_projection_views(xvfb_display, demo, tmp_path):
    """``view --stereo``: both eyes side by side in the window, each the fitted half view, equal
    to the headless render of that eye; ``--projection`` shows the model flat."""
    from splatgl.errors import ContextError
    from splatgl.api import default_camera
    from splatgl.scene.settings import RenderSettings
    from splatgl.renderers.stereo import eye_cameras
    from splatgl.viewer import controls
    from splatgl.viewer.app import Viewer, ViewerOptions

    path, scene = demo
    settings = RenderSettings(background=(0.1, 0.2, 0.3))
    options = ViewerOptions(visible=True, screenshot_dir=tmp_path, render_args=(str(path),),
                            vsync=False, stereo=0.05, projection="fisheye", fisheye_fov=180.0)
    try:
        v = Viewer(scene, settings, default_camera(scene, W, H), options=options)
    except ContextError as exc:
        pytest.skip(f"no OpenGL 4.3+ window context on Xvfb: {exc}")
    try:
        assert v.step(0.0)
        img = v.last.image
        assert img.shape[:2] == (v.size[1], v.size[0])
        cam = v.camera()
        assert cam.projection == "fisheye"
        half = controls.fit_camera(cam, cam.width // 2, cam.height)
        left = v.renderer.render(scene, eye_cameras(half, 0.05)[0], settings)
        np.testing.assert_array_equal(img[:, :half.width], left)
        assert not np.array_equal(img[:, :half.width], img[:, half.width:2 * half.width])
    finally:
        v.close()


def test_stereo_screenshot_is_the_pair_and_its_command_says_stereo(xvfb_display, demo, tmp_path, capsys):
    """F12 in stereo wrote one eye and a command without --stereo; now the PNG is the pair the
    window shows, and the printed command (with --stereo) writes the same file."""
    import shlex

    from splatgl.cli import main
    from splatgl.errors import ContextError
    from splatgl.imagefiles.images import read_image
    from splatgl.api import default_camera
    from splatgl.scene.settings import RenderSettings
    from splatgl.viewer.app import Viewer, ViewerOptions

    path, scene = demo
    options = ViewerOptions(visible=True, screenshot_dir=tmp_path, render_args=(str(path),),
                            vsync=False, stereo=0.05)
    try:
        v = Viewer(scene, RenderSettings(), default_camera(scene, 96, 48), options=options)
    except ContextError as exc:
        pytest.skip(f"no OpenGL 4.3+ window context on Xvfb: {exc}")
    try:
        assert v.step(0.0)
        png, js = v.screenshot()
        shown = v.last.image
    finally:
        v.close()
    command = capsys.readouterr().out.strip().splitlines()[-1].strip()
    argv = shlex.split(command)
    assert argv[:2] == ["splatgl", "render"] and argv[argv.index("--stereo") + 1] == "0.05"
    got = read_image(png)
    assert got.shape[:2] == shown.shape[:2] == (48, 96)
    assert np.abs(got - np.clip(shown[..., :3], 0, 1)).max() <= 0.5 / 255 + 1e-6
    again = tmp_path / "again.png"
    argv[argv.index("-o") + 1] = str(again)
    assert main(argv[1:]) == 0
    np.testing.assert_array_equal(read_image(again), got)


def test_t_skips_the_cpu_renderer_without_numba(viewer, monkeypatch):
    import glfw

    from splatgl.scene.settings import RendererKind
    from splatgl.renderers import registry

    v = viewer
    monkeypatch.setattr(registry, "installed", lambda kind: RendererKind(kind) is not RendererKind.CPU)
    v.on_key(glfw.KEY_T, glfw.PRESS, 0)
    assert v.kind is RendererKind.TILE and v.step()
    v.on_key(glfw.KEY_T, glfw.PRESS, 0)
    assert v.kind is RendererKind.QUAD
    assert v.message == "T skipped cpu: --renderer cpu needs numba: pip install 'splatgl[fast]'"


def test_equirectangular_view_refuses_the_tile_toggles(xvfb_display, demo, tmp_path):
    """T, C and Tab need the tile renderer, which has no panoramas: the viewer used to exit with
    code 2; now C and Tab change nothing, T goes on to the CPU renderer, and the status line
    says why."""
    import glfw

    from splatgl.errors import ContextError
    from splatgl.api import default_camera
    from splatgl.scene.settings import RenderSettings, RendererKind
    from splatgl.viewer.app import Viewer, ViewerOptions
    from splatgl.viewer.modes import ViewMode

    path, scene = demo
    options = ViewerOptions(visible=True, screenshot_dir=tmp_path, vsync=False,
                            projection="equirectangular")
    try:
        v = Viewer(scene, RenderSettings(), default_camera(scene, 64, 32), options=options)
    except ContextError as exc:
        pytest.skip(f"no OpenGL 4.3+ window context on Xvfb: {exc}")
    try:
        assert v.step(0.0)
        views = []
        v.on_key(glfw.KEY_T, glfw.PRESS, 0)     # T skips the tile renderer: quad -> cpu
        assert v.kind is RendererKind.CPU and v.step(0.0)
        assert v.message == ("T skipped tile: the tile renderer cannot draw equirectangular "
                             "images")
        v.on_key(glfw.KEY_T, glfw.PRESS, 0)
        assert v.kind is RendererKind.QUAD
        for key in ("C", "C", "TAB", "TAB", "TAB"):
            v.on_key(getattr(glfw, f"KEY_{key}"), glfw.PRESS, 0)
            v.step(0.0)
            assert v.kind is RendererKind.QUAD
            views.append(v.view)
        # one press, one view: Tab from the depth view goes straight back to colour
        assert views == [ViewMode.COLOR, ViewMode.COLOR, ViewMode.DEPTH, ViewMode.COLOR,
                         ViewMode.DEPTH]
        assert v.message == ("Tab skipped the difference view: the tile renderer cannot draw "
                             "equirectangular images")
        assert "fov 360x180 panorama" in "\n".join(v.overlay.lines)
    finally:
        v.close()


def test_ctrl_click_lists_the_pixel_from_the_reference(viewer, demo, capsys):
    """Ctrl+left click prints the pixel's splats (splatgl pixel's listing) and names the top
    one on the status line; it does not start an orbit drag."""
    import glfw

    from splatgl.reference.pixel import pixel_splats

    v = viewer
    v.step()
    state = v.state
    v.on_cursor(W / 2, H / 2)
    v.on_mouse_button(glfw.MOUSE_BUTTON_LEFT, glfw.PRESS, glfw.MOD_CONTROL)
    v.on_cursor(W / 2 + 40, H / 2)                        # no drag follows the click
    v.on_mouse_button(glfw.MOUSE_BUTTON_LEFT, glfw.RELEASE, glfw.MOD_CONTROL)
    assert v.state == state
    listing = v.last_pixel
    expected = pixel_splats(demo[1], v.camera(), W // 2, H // 2, v.settings)
    assert listing is not None and (listing.x, listing.y) == (W // 2, H // 2)
    assert [s.index for s in listing.splats] == [s.index for s in expected.splats] != []
    out = capsys.readouterr().out
    assert f"pixel ({W // 2}, {H // 2}):" in out and "weights sum" in out
    top = max(listing.splats, key=lambda s: s.weight)
    assert f"top splat {top.index}" in v.message
    # a marker shows the pixel listed (open in the middle), until the view changes
    from splatgl.viewer.display import MARKER_RADIUS

    v.overlay.visible = False
    v.step()
    arm = _window_pixels(v)[H // 2, W // 2 + MARKER_RADIUS - 1]
    assert tuple(arm) == (255, 0, 255)
    v.on_scroll(0.0, 1.0)
    v.step()
    assert tuple(_window_pixels(v)[H // 2, W // 2 + MARKER_RADIUS - 1]) != (255, 0, 255)


def test_view_benchmark_prints_its_figures_and_survives_an_older_benchmark(xvfb_display, demo,
                                                                          capsys, monkeypatch):
    """`view --benchmark N` prints the mean and the per-frame median and 10th percentile.
    The peer race's wrapper (../shared/peer-race/splatgl_bench.py) replaces Viewer.benchmark
    with a copy of an older body that returns the means only: the command printed the
    per-frame figures unconditionally and every wrapped run ended in a KeyError."""
    from splatgl.cli import main
    from splatgl.viewer.app import Viewer

    path, _ = demo
    argv = ["view", str(path), "--benchmark", "3", "--width", "96", "--height", "64"]
    assert main(argv) == 0
    out = capsys.readouterr().out
    line = next(x for x in out.splitlines() if x.startswith("benchmark: 3 frames at 96x64"))
    assert "up: -y (COLMAP convention) (U cycles +y / -y / +z / -z)" in out.splitlines()
    assert "median" in line and "10th percentile" in line, line
    monkeypatch.setattr(Viewer, "benchmark", lambda self, n: {"frame": 0.01, "sort": 0.001,
                                                              "draw": 0.008, "fps": 100.0})
    assert main(argv) == 0
    line = next(x for x in capsys.readouterr().out.splitlines() if x.startswith("benchmark:"))
    assert "100.00 fps" in line and "median" not in line, line


def test_k_in_a_fisheye_view_records_a_path_that_renders_the_fisheye(xvfb_display, demo, tmp_path, capsys):
    """K recorded the perspective cameras behind a lens view, so `render --path` drew a
    perspective flight unless --projection was repeated: the path file now names the
    projection, and its frames are the viewer's fisheye cameras (recorded in each frame)."""
    from dataclasses import replace

    import glfw

    from splatgl.api import default_camera
    from splatgl.cameras.fisheye import Fisheye
    from splatgl.cli import main
    from splatgl.datasets.sources import load_source
    from splatgl.errors import ContextError
    from splatgl.imagefiles.frame_record import camera_digest, read_record
    from splatgl.imagefiles.images import inspect_image
    from splatgl.scene.settings import RenderSettings
    from splatgl.viewer.app import Viewer, ViewerOptions

    path, scene = demo
    options = ViewerOptions(visible=True, screenshot_dir=tmp_path, render_args=(str(path),),
                            vsync=False, target_fps=0.0, projection="fisheye", fisheye_fov=200.0)
    try:
        v = Viewer(scene, RenderSettings(), default_camera(scene, 64, 48), options=options)
    except ContextError as exc:
        pytest.skip(f"no OpenGL 4.3+ window context on Xvfb: {exc}")
    try:
        v.step()
        w, h = v.size
        v.on_key(glfw.KEY_K, glfw.PRESS, 0)
        start = v.camera()
        v.state = replace(v.state, yaw=v.state.yaw + 10.0)
        v.recorder.keys.append((0.1, v.nav.camera(w, h)))
        end = v.camera()
        v.on_key(glfw.KEY_K, glfw.PRESS, 0)
    finally:
        v.close()
    recorded = tmp_path / "splatgl-view-path-0001.json"
    obj = json.loads(recorded.read_text())
    assert (obj["projection"], obj["projection_fov"]) == ("fisheye", 200.0)
    views, _ = load_source(recorded)
    assert isinstance(views[0].camera.model, Fisheye) and views[0].camera.fx == start.fx
    assert camera_digest(views[0].camera) == camera_digest(start)
    assert camera_digest(views[-1].camera) == camera_digest(end) != camera_digest(start)
    capsys.readouterr()
    assert main(["render", str(path), "--path", str(recorded), "-o", str(tmp_path / "f/")]) == 0
    assert f"wrote {len(views)} frames" in capsys.readouterr().out
    for k, cam in ((0, start), (len(views) - 1, end)):
        info = inspect_image(tmp_path / "f" / f"{k:05d}.png")
        assert read_record(info.description)["camera"] == camera_digest(cam)


def test_k_records_the_flight_as_a_path_file_and_b_changes_the_background(viewer, tmp_path, capsys):
    """K starts and stops recording: the path file (what `render --path` reads) starts at the
    camera K was pressed at and ends at the one it was stopped at; B cycles the background."""
    from dataclasses import replace

    import glfw

    from splatgl.datasets.sources import load_source
    from splatgl.viewer import recorder

    v = viewer
    v.step()
    start = v.camera()
    v.on_key(glfw.KEY_K, glfw.PRESS, 0)
    assert v.recorder.recording and v.message.startswith("recording")
    t0 = v.recorder._start
    for i in range(1, 4):                      # a flight of 0.3 s in three steps
        v.state = replace(v.state, yaw=v.state.yaw + 10.0)
        v.recorder.add(v.camera(), t0 + 0.1 * i)
    end = v.camera()
    path = v.recorder.stop(tmp_path, end, t0 + 0.4)
    assert path == tmp_path / "splatgl-view-path-0001.json"
    views, fps = load_source(path)
    assert fps == recorder.FPS and len(views) == round(0.4 * recorder.FPS) + 1
    assert np.allclose(views[0].camera.world_to_camera, start.world_to_camera, atol=1e-9)
    assert np.allclose(views[-1].camera.world_to_camera, end.world_to_camera, atol=1e-9)
    assert (views[0].camera.width, views[0].camera.height) == (W, H)
    v.on_key(glfw.KEY_K, glfw.PRESS, 0)        # through the key: a second file, its command
    v.state = replace(v.state, yaw=v.state.yaw + 10.0)
    v.recorder.keys.append((0.2, v.camera()))
    v.on_key(glfw.KEY_K, glfw.PRESS, 0)
    assert not v.recorder.recording and v.message == "saved splatgl-view-path-0002.json (splatgl render --path)"
    assert "--path " + str(tmp_path / "splatgl-view-path-0002.json") in capsys.readouterr().out

    v.on_key(glfw.KEY_I, glfw.PRESS, 0)
    v.on_key(glfw.KEY_B, glfw.PRESS, 0)        # (0.1, 0.2, 0.3) -> black -> white
    v.on_key(glfw.KEY_B, glfw.PRESS, 0)
    assert v.settings.background == (1.0, 1.0, 1.0) and v.message == "background 1,1,1"
    v.step()
    assert tuple(_window_pixels(v)[H - 1, 0]) == (255, 255, 255)


@pytest.mark.slow
def test_no_display_is_one_line_with_glfws_reason(tmp_path):
    """Issue 38: GLFW's reason came as a raw ``splatgl: warning: (65550) b'X11: ...'`` line
    before the error; it is now part of the one error line, decoded."""
    env = {k: v for k, v in os.environ.items() if k != "WAYLAND_DISPLAY"}
    r = subprocess.run([sys.executable, "-m", "splatgl", "view"], capture_output=True, text=True,
                       timeout=60, env={**env, "DISPLAY": ""}, cwd=tmp_path)
    assert r.returncode == 2 and "b'" not in r.stderr and "warning" not in r.stderr
    assert r.stderr.startswith("splatgl: error: cannot open a window: glfw failed to initialise "
                               "(X11: ") and r.stderr.count("\n") == 1
    assert r.stderr.endswith("; set DISPLAY, e.g. run under Xvfb)\n")


def test_renderer_auto_switches_to_the_cpu_renderer_once_its_kernels_compiled(viewer):
    """Issue 40 item 4: the viewer drew with quad while the CPU renderer's kernels compiled;
    the compiling thread sets ``switch_to`` and the next step draws the CPU renderer's exact
    frame, saying so; a renderer chosen meanwhile (T: the tile renderer) is kept."""
    pytest.importorskip("numba")
    from splatgl.scene.settings import RendererKind

    v = viewer
    assert v.step() and v.kind is RendererKind.QUAD
    v.switch_to = RendererKind.CPU
    assert v.step() and v.kind is RendererKind.CPU and not hasattr(v, "switch_to")
    assert v.message == "renderer auto -> cpu (its kernels are compiled)"
    v.kind = RendererKind.TILE
    v.switch_to = RendererKind.CPU
    v.step()
    assert v.kind is RendererKind.TILE
