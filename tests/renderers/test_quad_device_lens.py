"""The quad path's device-resident order (``--sort gpu``) for orthographic, fisheye and
equirectangular views (shaders/order_cull.comp's CULL_BOX and CULL_SPHERE twins), on llvmpipe.

The lens culls' decisions are float32 operations without transcendentals
(:func:`splatgl.order.lens_cull.cone_keeps`, :func:`~splatgl.order.lens_cull.seam_copies`,
the orthographic box of :func:`splatgl.order.cull.cull_visible`), made bit for bit on the
device: the device order is the CPU's (and its sort keys those of
:func:`~splatgl.order.lens_cull.lens_keys`), frames are identical, and a moving lens camera uploads only uniforms and reads
back only the image.  Omni-directional stereo keeps the CPU cull.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from helpers import compile_lib_check, shared_file
from splatgl.cameras.camera import Camera
from splatgl.cameras.equirect import WRAP_FLAG, Equirectangular
from splatgl.cameras.framing import default_camera
from splatgl.cameras.poses import look_at
from splatgl.cameras.registry import retarget
from splatgl.cameras.view import View
from splatgl.formats import load_scene
from splatgl.measure.stress import CASES
from splatgl.renderers.quad import QuadRenderer
from splatgl.renderers.quad_device import DeviceOrder
from splatgl.scene.settings import EarlyStop, RenderSettings, SortKey
from splatgl.scene.splats import Scene, SplatKind

REPO = Path(__file__).resolve().parents[2]
UPLOAD_BUDGET = 4096
LENSES = ("orthographic", "fisheye", "equirectangular")


def _scene(n: int = 4000, seed: int = 5) -> Scene:
    """Splats from faint to opaque, tiny to large, all around the cameras below."""
    rng = np.random.default_rng(seed)
    return Scene(rng.uniform(-1.5, 1.5, (n, 3)), rng.normal(size=(n, 4)),
                 rng.uniform(-7.0, -2.5, (n, 3)), rng.uniform(-6.0, 4.0, n),
                 rng.normal(0, 0.5, (n, 1, 3)))


def _lens_cameras(eye=(0.4, -0.3, -3.2)) -> dict[str, Camera]:
    pose = look_at(np.array(eye, float), np.zeros(3))
    inside = look_at(np.array([0.1, 0.2, -0.4]), np.array([0.5, 0.0, 1.0]))
    return {"orthographic": Camera.orthographic(80, 60, 20.0, pose),
            "fisheye": Camera.fisheye(64, 64, 190.0, inside),
            "fisheye-k": Camera.fisheye(80, 60, 150.0, pose, (0.05, -0.01, 0.002, 0.0)),
            "equirectangular": Camera.equirectangular(96, 48, inside)}


def _settings(key: SortKey, **changes) -> RenderSettings:
    return dataclasses.replace(RenderSettings(sort_key=key, early_stop=EarlyStop.OFF), **changes)


def _images(ctx, scene, cameras, **changes) -> list[tuple[np.ndarray, np.ndarray]]:
    """Each camera's frame with the CPU order and with the device order (which it drew)."""
    out = {}
    for key in (SortKey.EXACT, SortKey.GPU):
        settings = _settings(key, **changes)
        r = QuadRenderer(ctx, scene, settings)
        try:
            out[key] = [r.render(View.of(c, settings, scene)).rgba for c in cameras]
            assert r.last_times.device_order is (key is SortKey.GPU)
        finally:
            r.release()
    return list(zip(out[SortKey.EXACT], out[SortKey.GPU]))


@pytest.mark.parametrize("antialias", [False, True])
@pytest.mark.parametrize("name", list(_lens_cameras()))
def test_device_order_is_the_cpu_order(ctx, name, antialias):
    """The drawn order (indices, seam copies' flags) is the CPU cull's (the orthographic
    box's peak-alpha bound too: one float32 decision, splatgl.order.cull.peak_keeps)."""
    scene = _scene()
    camera = _lens_cameras()[name]
    settings = _settings(SortKey.GPU, antialias=antialias)
    r = QuadRenderer(ctx, scene, settings)
    try:
        view = View.of(camera, settings, scene)
        image = r.render(view).rgba
        assert r.last_times.device_order and image.any()
        got, want = r._device.order(), r.order(view)
        assert 0 < want.size
        if name == "orthographic":
            assert want.size < scene.count
        np.testing.assert_array_equal(got, want)
        if name == "equirectangular":
            assert (want >= WRAP_FLAG).any()      # seam copies made, on both sides the same
        elif name.startswith("fisheye"):
            assert want.size < scene.count         # the cone culls
    finally:
        r.release()


@pytest.mark.parametrize("name", ["fisheye", "fisheye-k", "equirectangular"])
def test_device_keys_are_lens_keys(ctx, name):
    """CULL_SPHERE against its twin splatgl.order.lens_cull.lens_keys() (NumPy path): the
    device's sorted (distance bits, index) pairs are lens_keys()' sorted uint64 keys bit for bit
    (seam copies with WRAP_FLAG; cone and near plane the same)."""
    from splatgl.order.cull import CullData
    from splatgl.order.lens_cull import lens_keys

    scene = _scene()
    settings = _settings(SortKey.GPU)
    r = QuadRenderer(ctx, scene, settings)
    try:
        view = View.of(_lens_cameras()[name], settings, scene)
        r.render(view)
        values = r._device.order()
        keys = np.frombuffer(r._device.sorter.buffers()[0].read(4 * values.size), np.uint32)
    finally:
        r.release()
    data = CullData.from_scene(scene)
    rows = np.flatnonzero(data.alive)
    out, path = lens_keys(data.subset(rows), rows.astype(np.uint32),
                          np.empty(2 * scene.count, np.uint64), view.frustum.camera, view.near,
                          view.scale)
    want = np.sort(out)
    assert path == "numpy" and 0 < want.size
    np.testing.assert_array_equal(keys, (want >> np.uint64(32)).astype(np.uint32))
    np.testing.assert_array_equal(values, (want & np.uint64(0xFFFFFFFF)).astype(np.uint32))
    if name == "equirectangular":
        assert (values >= WRAP_FLAG).any()
    elif name == "fisheye":
        assert want.size < rows.size               # the cone and the near plane cull


@pytest.mark.parametrize("antialias", [False, True])
def test_frames_are_identical_for_every_lens(ctx, antialias):
    cams = list(_lens_cameras().values()) + list(_lens_cameras((2.5, 0.5, 1.0)).values())
    for k, (a, b) in enumerate(_images(ctx, _scene(), cams, antialias=antialias)):
        assert a.any(), k
        np.testing.assert_array_equal(b, a, err_msg=f"camera {k}")


def _framed(scene: Scene, width: int, height: int) -> list[Camera]:
    base = default_camera(scene, width, height)
    return [default_camera(scene, width, height, projection="orthographic"),
            retarget(base, "fisheye"), retarget(base, "equirectangular"),
            default_camera(scene, width, height, distance_scale=0.2, projection="fisheye"),
            default_camera(scene, width, height, distance_scale=0.2,
                           projection="equirectangular")]


def test_demo_scene_lens_views_are_identical(ctx):
    scene = load_scene(REPO / "scenes" / "demo.ply")
    for k, (a, b) in enumerate(_images(ctx, scene, _framed(scene, 96, 64))):
        assert a.any(), k
        np.testing.assert_array_equal(b, a, err_msg=f"camera {k}")


@pytest.mark.slow
@pytest.mark.parametrize("name", ["ply/donut_sh0.ply", "compressed_ply/guitar.compressed.ply"])
def test_shared_scenes_lens_views_are_identical(ctx, shared_scenes, name):
    scene = load_scene(shared_file(shared_scenes, name), progress=lambda *a: None)
    for k, (a, b) in enumerate(_images(ctx, scene, _framed(scene, 128, 64))):
        assert a.any(), k
        np.testing.assert_array_equal(b, a, err_msg=f"camera {k}")


_STRESS = [c for c in CASES if not c.slow and "quad" not in c.unsupported]


@pytest.mark.parametrize("case", _STRESS, ids=[c.name for c in _STRESS])
def test_stress_cases_lens_views_are_identical(ctx, case):
    """Each fast stress case under its own pose as a fisheye and a panorama, and framed by an
    orthographic camera."""
    setup = case.build()
    cam = setup.camera
    cams = [retarget(cam, "fisheye"), retarget(cam, "equirectangular"),
            default_camera(setup.scene, cam.width, cam.height, projection="orthographic")]
    if setup.scene.kind is SplatKind.SURFEL_2D:   # lens cameras draw 3DGS only
        cams = [c for c in cams if c.model.draws_surfels]
    images = {}
    for key in (SortKey.EXACT, SortKey.GPU):
        settings = dataclasses.replace(setup.settings, sort_key=key, early_stop=EarlyStop.OFF)
        r = QuadRenderer(ctx, setup.scene, settings)
        try:
            images[key] = [r.render(View.of(c, settings, setup.scene)).rgba for c in cams]
        finally:
            r.release()
    for k, (a, b) in enumerate(zip(images[SortKey.EXACT], images[SortKey.GPU])):
        np.testing.assert_array_equal(b, a, err_msg=f"{case.name} camera {k}")


@pytest.mark.parametrize("name", LENSES)
def test_a_moving_lens_camera_uploads_uniforms_only_and_reads_back_the_image(ctx, name):
    scene = _scene()
    settings = _settings(SortKey.GPU)
    r = QuadRenderer(ctx, scene, settings)
    try:
        for k in range(3):
            cam = _lens_cameras((0.4 + 0.05 * k, -0.3, -3.2))[name]
            cam = cam if name != "equirectangular" else Camera.equirectangular(
                96, 48, look_at(np.array([0.1 + 0.05 * k, 0.2, -0.4]), np.array([0.5, 0, 1.0])))
            r.render(View.of(cam, settings, scene))
            t = r.last_times
            assert t.device_order and t.drawn == -1, k
            assert t.transfers.read_back == cam.width * cam.height * 16, k   # RGBA32F only
            assert t.transfers.uploaded <= UPLOAD_BUDGET, k
    finally:
        r.release()


def test_omni_directional_stereo_keeps_the_cpu_cull(ctx):
    """An ODS eye's offsets need arctan2/arcsin/cos/sin: the CPU cull with the device sort,
    the same image."""
    cam = _lens_cameras()["equirectangular"].with_model(Equirectangular(-0.032))
    assert not DeviceOrder.covers(View.of(cam, _settings(SortKey.GPU), _scene()))
    scene = _scene()
    settings = _settings(SortKey.GPU)
    r = QuadRenderer(ctx, scene, settings)
    try:
        gpu = r.render(View.of(cam, settings, scene)).rgba
        assert not r.last_times.device_order
    finally:
        r.release()
    cpu = QuadRenderer(ctx, scene, _settings(SortKey.EXACT))
    try:
        np.testing.assert_array_equal(gpu, cpu.render(View.of(cam, settings, scene)).rgba)
    finally:
        cpu.release()


def test_device_square_root_is_correctly_rounded_from_a_rough_estimate(ctx, tmp_path):
    """shaders/lib/sqrt_rn.glsl: from estimates off by up to 2 ulp (as a GPU's sqrt may be),
    the root is NumPy's float32 sqrt, bit for bit (the lens keys are distances)."""
    comp = compile_lib_check(
        ctx, tmp_path, ("sqrt_rn.glsl", "round_rn.glsl"),
        '#include "lib/sqrt_rn.glsl"\nlayout(local_size_x = 64) in;\n'
        'layout(std430, binding = 0) buffer Io { uint io[]; };\nuniform int u_off;\n'
        'void main() { uint i = gl_GlobalInvocationID.x; float a = uintBitsToFloat(io[i]);\n'
        '  uint s = floatBitsToUint(sqrt(a)); io[i] = floatBitsToUint('
        'sqrt_rn_from(a, uintBitsToFloat(uint(int(s) + u_off)))); }\n')
    rng = np.random.default_rng(3)
    a = np.concatenate([rng.uniform(1e-6, 1e6, 4096).astype(np.float32),
                        (rng.uniform(0.5, 64, 1024).astype(np.float32)) ** 2,   # near squares
                        np.float32([1.0, 4.0, 2.0, 0.25, 1e30, 1e-30, 3.9999998, 1.0000001])])
    a = np.concatenate([a, np.zeros((-a.size) % 64, np.float32) + 1.0])
    want = np.sqrt(a).view(np.uint32)
    for off in (-2, -1, 0, 1, 2):
        buf = ctx.buffer(a.tobytes())
        buf.bind_to_storage_buffer(0)
        comp["u_off"].value = off
        comp.run(group_x=a.size // 64)
        got = np.frombuffer(buf.read(), np.uint32)
        buf.release()
        np.testing.assert_array_equal(got, want, err_msg=f"estimate off by {off} ulp")
    comp.release()
