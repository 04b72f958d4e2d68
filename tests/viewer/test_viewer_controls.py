"""The viewer's pure input -> camera functions (no window, no OpenGL)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from splatgl.cameras.camera import Camera
from splatgl.cameras.poses import look_at
from splatgl.viewer import controls
from splatgl.viewer.controls import ViewState

W, H = 320, 240


@pytest.fixture
def state() -> ViewState:
    return ViewState(target=(0.5, -0.2, 1.0), distance=3.0, yaw=150.0, pitch=25.0, roll=10.0, fov_y=50.0)


def _dist(s: ViewState) -> float:
    return float(np.linalg.norm(controls.eye(s) - np.array(s.target)))


def test_camera_looks_at_target_from_distance(state):
    cam = controls.to_camera(state, W, H)
    assert np.allclose(cam.center, controls.eye(state))
    p = cam.world_to_camera @ np.append(state.target, 1.0)
    assert np.allclose(p[:2], 0.0, atol=1e-9) and p[2] == pytest.approx(state.distance)
    assert cam.height / (2 * cam.fy) == pytest.approx(math.tan(math.radians(25.0)))


@pytest.mark.parametrize("dx,dy", [(40, 0), (0, -30), (-200, 500), (1000, 1000)])
def test_orbit_keeps_distance_to_target(state, dx, dy):
    moved = controls.orbit_drag(state, dx, dy)
    assert moved.target == state.target
    assert _dist(moved) == pytest.approx(state.distance)
    assert not np.allclose(controls.eye(moved), controls.eye(state))
    assert -controls.PITCH_LIMIT <= moved.pitch <= controls.PITCH_LIMIT


def test_pan_moves_target_in_the_camera_plane(state):
    right, down, forward = controls.axes(state)
    moved = controls.pan(state, 30.0, -12.0, H)
    delta = np.array(moved.target) - np.array(state.target)
    assert abs(delta @ forward) < 1e-9
    assert np.linalg.norm(delta) > 0
    # The eye moves with the target: same orientation, same distance.
    assert np.allclose(controls.eye(moved) - controls.eye(state), delta)
    # The world point that was under the dragged pixel stays under the cursor.
    cam0, cam1 = controls.to_camera(state, W, H), controls.to_camera(moved, W, H)
    p = np.append(state.target, 1.0)
    u0 = (cam0.world_to_camera @ p)[:3]
    u1 = (cam1.world_to_camera @ p)[:3]
    px0 = np.array([cam0.fx * u0[0] / u0[2], cam0.fy * u0[1] / u0[2]])
    px1 = np.array([cam1.fx * u1[0] / u1[2], cam1.fy * u1[1] / u1[2]])
    assert np.allclose(px1 - px0, [30.0, -12.0])


def test_zoom_is_multiplicative(state):
    once = controls.zoom(state, 1.0)
    assert once.distance == pytest.approx(state.distance / controls.ZOOM_FACTOR)
    twice = controls.zoom(once, 1.0)
    assert twice.distance / once.distance == pytest.approx(once.distance / state.distance)
    assert controls.zoom(controls.zoom(state, 3.0), -3.0).distance == pytest.approx(state.distance)
    assert once.target == state.target


def test_fly_moves_along_view_axes(state):
    right, down, forward = controls.axes(state)
    e0 = controls.eye(state)
    assert np.allclose(controls.eye(controls.fly(state, forward=2.0)) - e0, 2.0 * forward)
    assert np.allclose(controls.eye(controls.fly(state, right=-0.5)) - e0, -0.5 * right)
    assert np.allclose(controls.eye(controls.fly(state, up=1.0)) - e0, -down)
    moved = controls.fly(state, 1.0, 1.0, 1.0)
    assert np.allclose(controls.axes(moved), controls.axes(state))  # orientation unchanged


def test_roll_turns_about_the_view_axis(state):
    rolled = controls.roll_by(state, 30.0)
    assert np.allclose(controls.eye(rolled), controls.eye(state))
    assert np.allclose(controls.axes(rolled)[2], controls.axes(state)[2])
    cos = controls.axes(rolled)[0] @ controls.axes(state)[0]
    assert cos == pytest.approx(math.cos(math.radians(30.0)))


def test_fov_changes_and_clamps(state):
    assert controls.change_fov(state, 4.0).fov_y == pytest.approx(54.0)
    assert controls.change_fov(state, -1000.0).fov_y == controls.FOV_RANGE[0]
    assert controls.change_fov(state, 1000.0).fov_y == controls.FOV_RANGE[1]


def test_reset_restores_home(state):
    s = controls.zoom(controls.pan(controls.orbit_drag(state, 50, 20), 5, 5, H), 2)
    s = controls.roll_by(controls.fly(s, 1, 2, 3), 40)
    assert s != state
    assert controls.reset(s, state) == state


def test_camera_stepping_cycles():
    seen = [0]
    for _ in range(7):
        seen.append(controls.step_index(seen[-1], 3, 1))
    assert seen == [0, 1, 2, 0, 1, 2, 0, 1]
    assert controls.step_index(0, 3, -1) == 2
    with pytest.raises(ValueError):
        controls.step_index(0, 0, 1)


@pytest.mark.parametrize("roll", [0.0, 33.0, -120.0])
def test_state_round_trips_through_a_camera(state, roll):
    s = ViewState(state.target, state.distance, state.yaw, state.pitch, roll, 40.0)
    cam = controls.to_camera(s, W, H)
    back = controls.from_camera(cam, s.distance)
    assert np.allclose(controls.world_to_camera(back), cam.world_to_camera, atol=1e-9)
    assert back.fov_y == pytest.approx(40.0)
    assert np.allclose(back.target, s.target)


def test_from_camera_reproduces_a_training_pose():
    pose = look_at([1.0, -2.0, -4.0], [0.2, 0.1, 0.3], up=(0.1, -1.0, 0.2))
    cam = Camera(640, 480, 500.0, 500.0, 320.0, 240.0, pose)
    s = controls.from_camera(cam, 2.5)
    got = controls.to_camera(s, 640, 480)
    assert np.allclose(got.world_to_camera, pose, atol=1e-9)
    assert got.fy == pytest.approx(500.0)


def test_screenshot_command_line_reproduces_the_settings():
    """The command printed with a screenshot parses back to the very same settings."""
    from splatgl.cli import build_parser
    from splatgl.commands._common import settings_from_args
    from splatgl.scene.settings import RendererKind, RenderSettings
    from splatgl.viewer.screenshot import settings_arguments

    settings = RenderSettings(background=(0.1, 0.2, 0.3), precision="rgba16f", extent="fast",
                              near=0.05, antialias=True, sh_degree=1, preprocess="vertex",
                              sort_key="bucket16", gpu_storage="compact")
    argv = ["render", "-o", "x.png", *settings_arguments(settings, RendererKind.QUAD)]
    args = build_parser().parse_args(argv)
    assert settings_from_args(args) == settings
    assert args.renderer == "quad"
    # the tile renderer's command carries only what it reads (the CLI refuses the rest)
    from splatgl.commands._common import check_convention
    argv = ["render", "-o", "x.png", *settings_arguments(settings, RendererKind.TILE)]
    args = build_parser().parse_args(argv)
    check_convention(args, RendererKind.TILE)
    assert settings_from_args(args) == RenderSettings(background=(0.1, 0.2, 0.3), near=0.05,
                                                      antialias=True, sh_degree=1,
                                                      gpu_storage="compact")
    assert args.renderer == "tile"


def test_fit_camera_keeps_a_file_cameras_own_intrinsics():
    import numpy as np

    from splatgl.cameras.camera import Camera
    from splatgl.cameras.poses import orbit
    from splatgl.viewer.controls import fit_camera

    cam = Camera(200, 100, 180.0, 150.0, 93.0, 57.0, orbit([0, 0, 0], 3.0, 10.0, 5.0))
    same = fit_camera(cam, 200, 100)
    assert (same.fx, same.fy, same.cx, same.cy) == (cam.fx, cam.fy, cam.cx, cam.cy)
    np.testing.assert_array_equal(same.world_to_camera, cam.world_to_camera)
    wide = fit_camera(cam, 500, 200)  # twice as tall, wider aspect: frame centred
    assert (wide.fx, wide.fy, wide.cy) == (360.0, 300.0, 114.0)
    assert wide.cx == 93.0 * 2 + 0.5 * (500 - 400)


def _panel_by_render_text(lines: list[str], size: int) -> np.ndarray:
    """The status panel drawn the direct way: render_text onto the panel, line by line."""
    import OpenImageIO as oiio

    from splatgl.viewer import overlay as o

    cells = [line.split("\t", 1) for line in lines]
    col2 = max((o._text_width(c[0], size) + 3 * o.PADDING for c in cells if len(c) == 2), default=0)
    w = max(o._text_width(c[0], size) if len(c) == 1 else col2 + o._text_width(c[1], size)
            for c in cells) + 2 * o.PADDING
    h = o.LINE_HEIGHT * len(lines) + 2 * o.PADDING
    buf = oiio.ImageBuf(oiio.ImageSpec(w, h, 4, oiio.FLOAT))
    oiio.ImageBufAlgo.fill(buf, (0.0, 0.0, 0.0, o.PANEL_ALPHA))
    for i, cell in enumerate(cells):
        for x, text in zip((o.PADDING, o.PADDING + col2), cell):
            if text.strip():
                oiio.ImageBufAlgo.render_text(buf, x, o.PADDING + o.LINE_HEIGHT * i + size - 2, text,
                                              size, "", (1.0, 1.0, 1.0, 1.0))
    return np.asarray(buf.get_pixels(oiio.FLOAT), np.float32).reshape(h, w, 4)


def test_status_panel_reuses_rendered_text_and_draws_what_render_text_draws(monkeypatch):
    """Each piece of text is rendered once and laid over the panel; the panel equals drawing
    every line with render_text directly (overhanging glyphs, two columns, the key list)."""
    import OpenImageIO as oiio

    from splatgl.viewer import overlay as o

    lines = ["quad  10.2 fps  frame 98.1 ms", "splats 23,456 drawn / 90,854", "gjpqy []{}|",
             "", "keys:"] + o.key_help("\t").splitlines()
    assert np.array_equal(o.text_image(lines), _panel_by_render_text(lines, o.FONT_SIZE))
    calls = []
    render_text = oiio.ImageBufAlgo.render_text
    monkeypatch.setattr(oiio.ImageBufAlgo, "render_text", lambda *a: calls.append(a) or render_text(*a))
    lines[0] = "quad  11.3 fps  frame 88.5 ms"          # the next refresh: one line changed
    panel = o.text_image(lines)
    assert [c[3] for c in calls] == [lines[0]]          # only the changed line is rendered
    assert np.array_equal(panel, _panel_by_render_text(lines, o.FONT_SIZE))


def _status(**changes):
    from splatgl.viewer.overlay import Status

    fields = dict(renderer="quad", fps=9.6, frame=0.1612, sort=0.0121, draw=0.1474,
                  splats="splats 45,624 drawn / 45,624", settings="rgba32f  SH 0/0  ellipse  bg 0,0,0",
                  size=(640, 360), fov="fov 50.0", view="colour", camera="",
                  quality="exact (as splatgl render)", moving=True)
    return Status(**{**fields, **changes})


def test_status_panel_shows_the_moving_rate_apart_from_the_exact_frames_cost():
    """With a budget: the rate of the moving frames, and what the last exact frame cost, whole
    (no shorter than its sort and draw); without one, the plain rate and the last frame."""
    from splatgl.viewer.overlay import status_lines

    lines = status_lines(_status())
    assert lines[0] == "quad  moving 9.6 fps  exact 161.2 ms (sort 12.1, draw 147.4)"
    assert lines[1] == "splats 45,624 drawn / 45,624"       # no "splats ... splats"
    assert status_lines(_status(moving=False, fps=6.2))[0] == \
        "quad  6.2 fps  frame 161.2 ms (sort 12.1, draw 147.4)"
    assert status_lines(_status(frame=0.0, fps=0.0))[0] == "quad  moving - fps  exact -"


def test_small_windows_get_a_compact_panel():
    """A 640x360 window: the panel covers about a third of it at full size, a small corner
    compact (the rate, the size and view, the quality and the message)."""
    from splatgl.viewer.overlay import Overlay, status_lines

    full, compact = Overlay(), Overlay()
    full.update(status_lines(_status(message="saved splatgl-view-0001.png")), 0.0)
    compact.update(status_lines(_status(message="saved splatgl-view-0001.png"), compact=True),
                   0.0, compact=True)
    area = lambda o: o.image.shape[0] * o.image.shape[1] / (640 * 360)   # noqa: E731
    assert area(full) > 0.2 and area(compact) < 0.12
    assert "saved splatgl-view-0001.png" in compact.lines
    assert compact.lines[0].startswith("quad  moving 9.6 fps  exact 161.2 ms")


def test_status_messages_expire():
    from splatgl.viewer.overlay import MESSAGE_SECONDS, Message

    m = Message()
    m.say("saved splatgl-view-0001.png", now=100.0)
    assert m.current(now=100.0 + MESSAGE_SECONDS - 0.1) == "saved splatgl-view-0001.png"
    assert m.current(now=100.0 + MESSAGE_SECONDS) == ""
    assert 2.0 <= MESSAGE_SECONDS <= 8.0


def test_lens_views_name_the_lens_field_of_view():
    """A fisheye shows the field of view it is drawn with (180 by default, as --help says),
    not the orbit's vertical one (115 for that fisheye's focal length)."""
    from splatgl.cameras.registry import retarget
    from splatgl.viewer.display import lens_fov

    cam = Camera.from_fov(640, 360, 50.0, np.eye(4))
    assert lens_fov(retarget(cam, "fisheye", None), 115.0) == "fov 180.0 fisheye"
    assert lens_fov(retarget(cam, "fisheye", 220.0), 115.0) == "fov 220.0 fisheye"
    assert lens_fov(retarget(cam, "equirectangular"), 90.0) == "fov 360x180 panorama"
    assert lens_fov(cam, 50.0) == "fov 50.0"


@pytest.mark.parametrize("x, y, steps", [(40.0, 30.0, 1.0), (300.0, 200.0, -2.0), (160.0, 120.0, 3.0)])
def test_zoom_keeps_the_point_under_the_cursor(state, x, y, steps):
    """Wheel over a point: the point of the target's plane under the cursor stays there (the
    window's centre zooms straight in, as before)."""
    cam = controls.to_camera(state, W, H)
    right, down, forward = controls.axes(state)
    s = controls.world_per_pixel(state, H)
    point = np.array(state.target) + right * (x - W / 2) * s + down * (y - H / 2) * s
    zoomed = controls.zoom_at(state, steps, x, y, W, H)
    assert zoomed.distance == pytest.approx(controls.zoom(state, steps).distance)
    for c in (cam, controls.to_camera(zoomed, W, H)):
        p = c.world_to_camera @ np.append(point, 1.0)
        assert (c.fx * p[0] / p[2] + c.cx, c.fy * p[1] / p[2] + c.cy) == pytest.approx((x, y), abs=1e-6)
    centre = controls.zoom_at(state, steps, W / 2, H / 2, W, H)
    assert np.allclose(centre.target, state.target) and centre.distance == zoomed.distance


def test_zooming_out_for_ever_keeps_a_camera_the_renderers_take():
    """Issue 38: a camera beyond float32's reach is refused (one line); the viewer's wheel must
    never make one, however many steps it turns."""
    state = ViewState(target=(0.0, 0.0, 0.0), distance=3.0)
    for _ in range(400):   # 1.15 ** 400 ~ 2e24
        state = controls.zoom(state, -1)
    assert state.distance == controls.MAX_DISTANCE
    camera = controls.to_camera(state, 64, 48)
    assert np.isfinite(camera.world_to_camera).all()
