"""The quad path's device-resident order (``--sort gpu``, splatgl/renderers/quad_device.py) and
the frame's transfer accounting (splatgl/gl/transfers.py), on llvmpipe.

The device cull (shaders/order_cull.comp) keeps what the CPU cull keeps, in the same order
(the peak-alpha bound decided in float32 on both); frames are identical to the CPU order's (early termination off on both here; with it
on: test_quad_device_stop.py; lens views: test_quad_device_lens.py); a moving-camera frame
uploads only uniforms and its 16-byte draw command and reads back only the image.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from helpers import compile_lib_check, shared_file
from splatgl.cameras.camera import Camera
from splatgl.cameras.opencv import OpenCV
from splatgl.cameras.poses import look_at
from splatgl.cameras.view import View
from splatgl.cli import main
from splatgl.formats import load_scene
from splatgl.scene.splats import Scene
from splatgl.scene.settings import EarlyStop, Preprocess, RenderSettings, SortKey
from splatgl.order.chunks import ChunkedCull
from splatgl.order.stage import cull_for
from splatgl.renderers.quad import QuadRenderer
from splatgl.measure.stress import CASES

REPO = Path(__file__).resolve().parents[2]
#: What a moving-camera frame may upload on llvmpipe (issue 40: at most 4 KB).
UPLOAD_BUDGET = 4096


def _scene(n: int = 4000, seed: int = 5) -> Scene:
    """Splats from faint to opaque, tiny to large, some outside every view used below."""
    rng = np.random.default_rng(seed)
    return Scene(rng.uniform(-1.5, 1.5, (n, 3)), rng.normal(size=(n, 4)),
                 rng.uniform(-7.0, -2.5, (n, 3)), rng.uniform(-6.0, 4.0, n),
                 rng.normal(0, 0.5, (n, 1, 3)))


def _cameras() -> list[Camera]:
    pose = look_at(np.array([0.4, -0.3, -3.2]), np.zeros(3))
    inside = look_at(np.array([0.1, 0.2, -0.4]), np.array([0.5, 0.0, 1.0]))
    pin = Camera.from_fov(80, 60, 55.0, pose)
    return [pin, Camera.from_fov(64, 48, 30.0, inside), pin.with_model(OpenCV(k1=-0.3, k2=0.05))]


def _settings(key: SortKey, **changes) -> RenderSettings:
    return dataclasses.replace(RenderSettings(sort_key=key, early_stop=EarlyStop.OFF), **changes)


def _frames(ctx, scene, cameras, settings) -> tuple[list[np.ndarray], QuadRenderer]:
    r = QuadRenderer(ctx, scene, settings)
    return [r.render(View.of(c, settings, scene)).rgba for c in cameras], r


def _assert_cpu_order(r: QuadRenderer, scene: Scene, view: View, antialias: bool):
    """The device's drawn order is the CPU's (the same kept splats: the peak-alpha bound is
    decided in float32 on both, splatgl.order.cull.peak_keeps), with the CPU's depth bits as
    keys."""
    got, want = r._device.order(), r.order(view)
    np.testing.assert_array_equal(got, want)
    if got.size == 0:
        return
    keys = np.frombuffer(r._device.sorter.buffers()[0].read(4 * got.size), np.uint32)
    cpu_keys = np.sort(cull_for(view).scene(ChunkedCull.from_scene(scene), view, antialias))
    np.testing.assert_array_equal(keys, (cpu_keys >> np.uint64(32)).astype(np.uint32))


@pytest.mark.parametrize("antialias", [False, True])
@pytest.mark.parametrize("camera", _cameras(), ids=["pinhole", "inside", "opencv"])
def test_device_cull_is_the_cpu_cull(ctx, camera, antialias):
    scene = _scene()
    settings = _settings(SortKey.GPU, antialias=antialias)
    r = QuadRenderer(ctx, scene, settings)
    try:
        view = View.of(camera, settings, scene)
        r.render(view)
        assert r.last_times.device_order
        assert 0 < r.order(view).size < scene.count            # the cull drops splats here
        _assert_cpu_order(r, scene, view, antialias)
    finally:
        r.release()


@pytest.mark.parametrize("preprocess", [Preprocess.COMPUTE, Preprocess.VERTEX])
@pytest.mark.parametrize("antialias", [False, True])
def test_frames_are_identical_to_the_cpu_order(ctx, preprocess, antialias):
    scene = _scene()
    cams = _cameras()
    images = {}
    for key in (SortKey.EXACT, SortKey.GPU):
        images[key], r = _frames(ctx, scene, cams, _settings(key, preprocess=preprocess,
                                                            antialias=antialias))
        r.release()
    for k, (a, b) in enumerate(zip(images[SortKey.EXACT], images[SortKey.GPU])):
        assert a.any(), k
        np.testing.assert_array_equal(b, a, err_msg=f"camera {k}")


def test_demo_scene_and_its_views_are_identical(ctx):
    scene = load_scene(REPO / "scenes" / "demo.ply")
    centre = scene.means.mean(axis=0)
    cams = [Camera.from_fov(96, 72, 50.0, look_at(centre + d, centre))
            for d in (np.array([0.0, -0.5, -4.0]), np.array([3.0, 0.2, 0.5]),
                      np.array([0.3, 0.3, -0.6]))]
    exact, r = _frames(ctx, scene, cams, _settings(SortKey.EXACT))
    r.release()
    gpu, r = _frames(ctx, scene, cams, _settings(SortKey.GPU))
    r.release()
    for a, b in zip(exact, gpu):
        np.testing.assert_array_equal(b, a)


def test_a_shared_scene_is_identical(ctx, shared_scenes):
    scene = load_scene(shared_file(shared_scenes, "ply/donut_sh0.ply"))
    centre = np.median(scene.means, axis=0)
    radius = float(np.percentile(np.linalg.norm(scene.means - centre, axis=1), 90))
    cams = [Camera.from_fov(128, 96, 50.0, look_at(centre + radius * d, centre))
            for d in (np.array([0.0, -0.6, -2.0]), np.array([1.5, -0.3, 0.4]))]
    exact, r = _frames(ctx, scene, cams, _settings(SortKey.EXACT))
    r.release()
    gpu, r = _frames(ctx, scene, cams, _settings(SortKey.GPU))
    assert r.last_times.device_order
    r.release()
    for a, b in zip(exact, gpu):
        np.testing.assert_array_equal(b, a)


_STRESS = [c for c in CASES if not c.slow and "quad" not in c.unsupported]


@pytest.mark.parametrize("case", _STRESS, ids=[c.name for c in _STRESS])
def test_stress_cases_are_identical(ctx, case):
    setup = case.build()
    images = []
    for key in (SortKey.EXACT, SortKey.GPU):
        settings = dataclasses.replace(setup.settings, sort_key=key, early_stop=EarlyStop.OFF)
        frames, r = _frames(ctx, setup.scene, [setup.camera], settings)
        r.release()
        images.append(frames[0])
    np.testing.assert_array_equal(images[1], images[0])


def test_a_moving_camera_uploads_uniforms_only_and_reads_back_the_image(ctx):
    scene = _scene()
    cams = [Camera.from_fov(80, 60, 55.0, look_at(np.array([0.4 + 0.05 * k, -0.3, -3.2]),
                                                  np.zeros(3))) for k in range(4)]
    settings = _settings(SortKey.GPU)
    r = QuadRenderer(ctx, scene, settings)
    cpu = QuadRenderer(ctx, scene, _settings(SortKey.EXACT))
    try:
        image_bytes = 80 * 60 * 16   # RGBA32F
        for k, cam in enumerate(cams):
            r.render(View.of(cam, settings, scene))
            t = r.last_times
            assert t.device_order and t.drawn == -1
            assert t.transfers.read_back == image_bytes, k
            assert t.transfers.uploaded <= UPLOAD_BUDGET, k   # no splat crosses the bus
            assert t.transfers.syncs <= 3, k     # the draw's finish, the prepass's, the read
        cpu.render(View.of(cams[-1], settings, scene))   # the CPU order uploads its indices
        assert cpu.last_times.transfers.uploaded >= 4 * 1000
    finally:
        r.release()
        cpu.release()


def test_timings_report_the_frame_transfers(tmp_path, capsys):
    out = tmp_path / "a.png"
    assert main(["render", str(REPO / "scenes" / "demo.ply"), "--width", "48", "--height", "32",
                 "-o", str(out), "--sort", "gpu", "--timings"]) == 0
    line = [s for s in capsys.readouterr().out.splitlines() if s.startswith("timings")][0]
    assert "per-frame uploads " in line and f"read back {48 * 32 * 16:,} bytes" in line
    assert " syncs" in line


def test_window_frames_move_no_splat_and_read_nothing_back(gl_renderer):
    """The viewer's frames (drafts at a lower scale, the exact one, as the window draws them)
    read nothing back with ``--sort gpu`` and upload only uniforms; the status panel says so."""
    from splatgl.interactive.budget import EXACT, Level
    from splatgl.interactive.draft import LevelRenderer
    from splatgl.viewer.modes import splats_phrase

    scene = _scene()
    settings = RenderSettings(sort_key=SortKey.GPU)
    drafts = LevelRenderer(gl_renderer, scene, settings)
    try:
        for k, level in enumerate((Level(0.5, None, 0), EXACT, EXACT)):
            cam = Camera.from_fov(96, 72, 55.0, look_at(np.array([0.4 + 0.1 * k, -0.3, -3.2]),
                                                        np.zeros(3)))
            frame = drafts.draw(cam, level, on_batch=lambda done, total: None)
            assert frame.device_order and frame.splats == scene.count
            assert frame.transfers.read_back == 0, level
            assert frame.transfers.uploaded <= UPLOAD_BUDGET, level
        text = splats_phrase(frame, scene.count)
        assert text.startswith("splats counted on the device / 4,000; per-frame uploads ")
        assert "read back 0 bytes" in text
    finally:
        drafts.release()


@pytest.mark.parametrize("n, target", [(70_001, np.zeros(3)), (3000, np.array([0.0, 0.0, -9.0]))],
                         ids=["scan-runs", "nothing-kept"])
def test_the_compaction_keeps_index_order_across_groups(ctx, n, target):
    """order_scan.comp's runs (more groups than its threads: several each) and a view that
    keeps nothing: the device's kept rows and order are the CPU's."""
    scene = _scene(n, seed=n)
    cam = Camera.from_fov(40, 30, 40.0, look_at(np.array([0.2, 0.1, -3.5]), target))
    settings = _settings(SortKey.GPU)
    r = QuadRenderer(ctx, scene, settings)
    try:
        view = View.of(cam, settings, scene)
        image = r.render(view).rgba
        _assert_cpu_order(r, scene, view, False)
        assert (r._device.kept() == 0) == (not image.any())
    finally:
        r.release()


def test_depth_layer_and_geometry_under_are_identical(ctx):
    """The depth layer (same pass) and a geometry depth test (``under``) with the device order."""
    from splatgl.output.layers import Layer, with_layers
    from splatgl.output.under import UnderLayer

    scene = _scene()
    cam = _cameras()[0]
    depth = np.full((cam.height, cam.width), 3.3, np.float32)
    depth[:, : cam.width // 2] = np.inf
    under = UnderLayer(np.zeros((cam.height, cam.width, 3), np.float32),
                       np.zeros((cam.height, cam.width), np.float32), depth)
    outs = []
    for key in (SortKey.EXACT, SortKey.GPU):
        settings = _settings(key)
        r = QuadRenderer(ctx, scene, settings)
        try:
            view = View.of(cam, settings, scene)
            outs.append((r.render(view, with_layers(Layer.DEPTH)), r.render(view, under=under)))
            assert r.last_times.device_order is (key is SortKey.GPU)
        finally:
            r.release()
    (a_depth, a_under), (b_depth, b_under) = outs
    np.testing.assert_array_equal(b_depth.rgba, a_depth.rgba)
    np.testing.assert_array_equal(b_depth.expected_depth(), a_depth.expected_depth())
    np.testing.assert_array_equal(b_under.rgba, a_under.rgba)


def test_the_viewers_colour_frame_reads_nothing_back(gl_renderer):
    """The window's own quad frame (viewer/modes.py, no budget) with ``--sort gpu``: its
    status line says the order stayed on the device and nothing was read back."""
    from splatgl.scene.settings import RendererKind
    from splatgl.viewer.modes import ViewMode, render_frame

    scene = _scene()
    settings = RenderSettings(sort_key=SortKey.GPU)
    for k in range(2):   # the second frame: the programs already made
        cam = Camera.from_fov(96, 72, 55.0, look_at(np.array([0.4 + 0.1 * k, -0.3, -3.2]),
                                                    np.zeros(3)))
        frame = render_frame(gl_renderer, scene, cam, settings, RendererKind.QUAD, ViewMode.COLOR)
    assert frame.texture is not None and frame.image is None
    assert frame.splats.startswith("splats counted on the device / 4,000; per-frame uploads ")
    assert "read back 0 bytes" in frame.splats
    uploaded = int(frame.splats.split("per-frame uploads ")[1].split(" bytes")[0].replace(",", ""))
    assert uploaded <= UPLOAD_BUDGET


def test_device_division_is_correctly_rounded_from_a_rough_estimate(ctx, tmp_path):
    """shaders/lib/div_rn.glsl: from quotients off by up to 3 ulp (GLSL allows 2.5), the
    quotient is NumPy's float32 a / b, bit for bit (order_cull.comp's peak-alpha decision)."""
    comp = compile_lib_check(
        ctx, tmp_path, ("div_rn.glsl", "round_rn.glsl"),
        '#include "lib/div_rn.glsl"\nlayout(local_size_x = 64) in;\n'
        'layout(std430, binding = 0) buffer Io { uint io[]; };\nuniform int u_off;\n'
        'void main() { uint i = gl_GlobalInvocationID.x; float a = uintBitsToFloat(io[2u * i]);\n'
        '  float b = uintBitsToFloat(io[2u * i + 1u]); uint q = floatBitsToUint(a / b);\n'
        '  io[2u * i] = floatBitsToUint(div_rn_from(a, b, uintBitsToFloat(uint(int(q) + u_off)))); }\n')
    rng = np.random.default_rng(4)
    n = 8192
    a = (rng.uniform(-1, 1, n) * 10.0 ** rng.uniform(-8, 8, n)).astype(np.float32)
    b = (rng.uniform(0.1, 1, n) * 10.0 ** rng.uniform(-8, 8, n)).astype(np.float32)
    b[: n // 8] = rng.integers(1, 4096, n // 8).astype(np.float32)     # exact quotients
    a[: n // 8] = b[: n // 8] * rng.integers(-4096, 4096, n // 8).astype(np.float32)
    a[n // 8: n // 4] = np.float32(0.3)                                 # LOW_PASS / lambda
    b[n // 8: n // 4] = np.float32(0.3) + rng.uniform(0, 100, n // 8).astype(np.float32)
    b[-3:] = -b[-3:]
    want = (a / b).view(np.uint32)
    io = np.stack([a.view(np.uint32), b.view(np.uint32)], 1)
    for off in (-3, -1, 0, 1, 3):
        buf = ctx.buffer(io.tobytes())
        buf.bind_to_storage_buffer(0)
        comp["u_off"].value = off
        comp.run(group_x=n // 64)
        got = np.frombuffer(buf.read(), np.uint32)[0::2]
        buf.release()
        zero = a == 0   # a zero quotient keeps the estimate
        np.testing.assert_array_equal(got[~zero], want[~zero], err_msg=f"estimate off by {off} ulp")
    comp.release()
