"""The chunked cull (:mod:`splatgl.order.chunks`) and the fused lens cull (:mod:`splatgl.order.lens_cull`)
keep exactly what the float64 cull and the old lens stages keep, with the same depth bits, so
the sorted order (and so the image) is unchanged; on random scenes and cameras and on a real one.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from splatgl.order import chunks as cull_chunks, kernels as cull_kernel
from splatgl.cameras.equirect import WRAP_FLAG, Equirectangular
from splatgl.cameras.fisheye import Fisheye, fisheye_theta_limit
from splatgl.cameras.registry import retarget
from splatgl.order.lens_cull import cone_keeps, lens_cull, lens_order
from splatgl.splatmath.project import splat_reach
from splatgl.cameras.camera import Camera
from splatgl.cameras.poses import look_at
from splatgl.order.cull import CullData, cull
from splatgl.order.chunks import ChunkedCull, keys_order, keys_pairs
from splatgl.order.lens_cull import lens_visible_keys
from splatgl.cameras.view import anchored_camera
from splatgl.splatmath.project import to_camera
from splatgl.order.sort import depth_keys, depth_sort

FISHEYE_K = (0.05, -0.01, 0.002, -0.0003)


def _clustered(n: int, seed: int):
    """(N, 3) float32 centres in clusters (so whole chunks fall inside and outside a view),
    log-normal max scales with some large splats, opacities spanning the faint range."""
    rng = np.random.default_rng(seed)
    centres = rng.uniform(-4, 4, (max(n // 200, 1), 3))
    points = (centres[rng.integers(0, len(centres), n)] + rng.normal(0, 0.25, (n, 3)))
    max_scale = np.exp(rng.normal(-3.5, 1.0, n))
    opac = np.concatenate([rng.uniform(0, 0.02, n // 5), rng.uniform(0, 1, n - n // 5)])
    return points.astype(np.float32), max_scale.astype(np.float32), rng.permutation(opac).astype(np.float32)


def _want_keys(points, max_scale, opac, camera, near, antialias=False):
    """Sorted keys of the float64 cull's splats with float32 camera-space z."""
    keep = np.flatnonzero(cull(to_camera(points, camera), max_scale * camera.scale, opac, camera,
                               near, antialias))
    z = to_camera(points, camera)[keep, 2]
    return np.sort(depth_keys(z, keep.astype(np.uint32)))


def _cameras():
    far = look_at(np.array([0.3, -0.5, -7.0]), np.array([3.0, 1.0, 0.0]))
    inside = look_at(np.array([0.2, 0.1, -0.5]), np.array([1.0, 0.5, 2.0]))
    edge = look_at(np.array([-9.0, 0.0, -4.0]), np.array([2.0, 0.0, 3.0]))
    scaled = far.copy()
    scaled[:3, :3] *= 2.5  # a scene transform's uniform scale folded in
    return [Camera.from_fov(640, 360, 50.0, far), Camera.from_fov(300, 400, 80.0, inside),
            Camera(320, 200, 260.0, 240.0, 40.0, 170.0, edge),
            Camera.from_fov(640, 360, 30.0, scaled), Camera.orthographic(200, 150, 40.0, far)]


def _need_kernel():
    """The compiled cull, loaded (the test extra installs numba; a load that fails is a bug)."""
    if not cull_kernel.installed():
        pytest.skip("numba not installed (pip install '.[fast]')")
    assert cull_kernel.kernel(wait=True) is not None, "numba is installed but the kernel failed to load"


PATHS = {"chunks": (1.0, False, False), "one-pass": (0.0, False, False),
         "compiled": (1.0, True, False), "compiled-2-threads": (1.0, True, True)}


@pytest.mark.parametrize("path", PATHS)
@pytest.mark.parametrize("antialias", [False, True])
@pytest.mark.parametrize("cam_index", range(5))
def test_chunked_cull_keeps_what_the_float64_cull_keeps(cam_index, antialias, path, monkeypatch):
    """Through the chunks (boundary rows never handed to the one-pass fallback), through the
    fallback, and through the compiled pass (numba; antialiasing and orthographic cameras take
    the NumPy path there too), on one thread and split over two."""
    whole_share, compiled, split = PATHS[path]
    if compiled:
        _need_kernel()
    monkeypatch.setattr(cull_chunks, "WHOLE_SHARE", whole_share)
    monkeypatch.setattr(cull_chunks, "SPLIT_ROWS", 1 if split else 10 ** 9)
    points, max_scale, opac = _clustered(30_000, 3 + cam_index)
    camera = _cameras()[cam_index]
    chunks = ChunkedCull(CullData(points, max_scale, opac), chunk=32, group=8)
    chunks.compiled = compiled
    assert bool(chunks._split) == split
    got = np.sort(chunks.visible_keys(camera, 0.05, antialias, camera.scale))
    assert chunks.last_path == ("compiled" if compiled and not antialias
                                and not camera.is_orthographic else "numpy")
    want = _want_keys(points, max_scale, opac, camera, 0.05, antialias)
    assert 0 < want.size < points.shape[0]
    np.testing.assert_array_equal(got, want)
    if not camera.is_orthographic:  # every kind of chunk occurs, so each branch was checked
        accept, reject = chunks.chunks.classify(camera, 0.05, camera.scale)
        assert accept.any() and reject.any() and (~(accept | reject)).any()


@settings(max_examples=25)
@given(seed=st.integers(0, 10_000), eye=st.tuples(*[st.floats(-8, 8)] * 3),
       target=st.tuples(*[st.floats(-3, 3)] * 3), fov=st.floats(20, 120),
       cx=st.floats(-50, 350), near=st.floats(0.01, 2.0), scale=st.floats(0.3, 3.0))
def test_chunked_cull_property(compiled_kernels, seed, eye, target, fov, cx, near, scale):
    """Any pose, field of view, principal point, near plane and transform scale: the same splats,
    the same depth bits as the float64 cull (ties and ordering then follow)."""
    eye, target = np.array(eye), np.array(target)
    if np.linalg.norm(eye - target) < 1e-3:
        return
    pose = look_at(eye, target)
    pose[:3, :3] *= scale
    camera = dataclasses.replace(Camera.from_fov(300, 200, fov, pose), cx=cx)
    points, max_scale, opac = _clustered(4000, seed)
    chunks = ChunkedCull(CullData(points, max_scale, opac), chunk=16, group=4)
    want = _want_keys(points, max_scale, opac, camera, near)
    share, cull_chunks.WHOLE_SHARE = cull_chunks.WHOLE_SHARE, 1.0  # always through the chunks
    try:
        for compiled in ([False, True] if cull_kernel.installed() else [False]):
            chunks.compiled = compiled
            got = np.sort(chunks.visible_keys(camera, near, False, camera.scale))
            np.testing.assert_array_equal(got, want)
    finally:
        cull_chunks.WHOLE_SHARE = share


def test_keys_order_and_pairs_feed_every_sort_as_before():
    """The exact sort of the keys is depth_sort's order; keys_pairs gives the device and bucket
    sorts ascending indices with their depths, seam copies after the rest."""
    rng = np.random.default_rng(5)
    idx = np.sort(rng.choice(5000, 1200, replace=False)).astype(np.uint32)
    z = rng.choice(np.float32([0.5, 1.0, 2.0, 3.5]), idx.size)  # many ties
    copies = idx[::7] | WRAP_FLAG
    keys = rng.permutation(np.concatenate([depth_keys(z, idx), depth_keys(z[::7], copies)]))
    all_z, all_idx = np.concatenate([z, z[::7]]), np.concatenate([idx, copies])
    np.testing.assert_array_equal(keys_order(keys), depth_sort(all_z, all_idx))
    depth, index = keys_pairs(keys, 5000)
    np.testing.assert_array_equal(index, all_idx)
    np.testing.assert_array_equal(depth, all_z)


def _old_lens_keys(points, max_scale, opac, camera, near, cone_rows=0):
    """The lens stages as the quad path ran them before the fused cull (sorted keys); the first
    ``cone_rows`` rows (on a fisheye's angle-limit cone) decided by the float32 cone test
    :func:`~splatgl.order.lens_cull.cone_keeps` (the decision the device order shares) instead
    of the model's ``arctan2``: the two differ only within rounding of the cone."""
    p_cam = to_camera(points, camera)
    mask = lens_cull(p_cam, opac, camera, near)
    if cone_rows:
        p = p_cam[:cone_rows]
        d = camera.model.depth(p).astype(np.float32)
        cos_limit = np.float32(np.cos(fisheye_theta_limit(camera)))
        mask[:cone_rows] = (d > np.float32(near)) & (opac[:cone_rows] >= 1 / 255) & cone_keeps(
            p[:, 2], d, cos_limit)
        assert mask[:cone_rows].any() and not mask[:cone_rows].all()   # the cone is straddled
    kept = np.flatnonzero(mask)
    reach = splat_reach(max_scale[kept] * camera.scale, opac[kept])
    depth, keep = lens_order(p_cam, kept, reach, camera)
    return np.sort(depth_keys(depth, keep)), keep


def _lens_cameras():
    pose = look_at(np.array([0.5, -0.3, -1.0]), np.array([0.0, 0.0, 2.0]))
    return [Camera.fisheye(96, 64, 200, pose, FISHEYE_K), Camera.fisheye(64, 64, 120, pose),
            Camera.equirectangular(128, 64, pose),
            Camera.equirectangular(128, 64, pose).with_model(Equirectangular(-0.032))]


@pytest.mark.parametrize("path", ["numpy", "compiled", "compiled-2-threads"])
@pytest.mark.parametrize("cam_index", range(4), ids=["fisheye_k", "fisheye", "equirect", "ods"])
def test_lens_cull_keeps_what_the_old_lens_stages_keep(cam_index, path, monkeypatch):
    """NumPy and compiled (one thread, two; an ODS camera takes the NumPy path there too)."""
    if path != "numpy":
        _need_kernel()
    monkeypatch.setattr(cull_chunks, "SPLIT_ROWS", 1 if path.endswith("threads") else 10 ** 9)
    points, max_scale, opac = _clustered(20_000, 17)
    camera = _lens_cameras()[cam_index]
    if isinstance(camera.model, Fisheye):
        # splats on the angle limit's cone, inside and outside by float32 rounding: the float32
        # cone test decides them (cone_keeps)
        limit = fisheye_theta_limit(camera)
        theta = limit + np.linspace(-3e-6, 3e-6, 600)
        phi = np.linspace(0, 2 * np.pi, 600)
        cone = np.stack([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)], 1) * 2.0
        world = (cone - camera.translation) @ camera.rotation  # camera -> world
        points[:600] = world.astype(np.float32)
    chunks = ChunkedCull(CullData(points, max_scale, opac), chunk=32, group=8)
    chunks.compiled = path != "numpy"
    want, keep = _old_lens_keys(points, max_scale, opac, camera, 0.05,
                                600 if isinstance(camera.model, Fisheye) else 0)
    got = np.sort(lens_visible_keys(chunks, camera, 0.05, camera.scale))
    assert chunks.last_path == ("compiled" if path != "numpy" and not getattr(camera.model, "ods_eye", 0.0) else "numpy")
    np.testing.assert_array_equal(got, want)
    assert 0 < want.size
    if isinstance(camera.model, Equirectangular):
        assert (keep >= WRAP_FLAG).any()  # seam copies were made and matched
    else:
        assert want.size < points.shape[0]


@pytest.mark.parametrize("name", ["ply/donut_sh0.ply", "compressed_ply/biker.compressed.ply"])
def test_real_scene_orders_unchanged(shared_scenes, name):
    """On real scenes, pinhole (framing and close), fisheye and equirect views: the quad path's
    new cull stages give exactly the order of the old stages (cull_visible + depth_sort, and
    lens_cull + lens_order + depth_sort), so the rendered images are identical."""
    from splatgl.cameras.poses import orbit
    from splatgl.order.cull import cull_visible
    from splatgl.formats import load_scene
    from splatgl.api import default_camera
    from splatgl.scene.settings import RenderSettings, resolve_near

    from helpers import shared_file

    scene = load_scene(shared_file(shared_scenes, name), progress=lambda *a: None)
    near = resolve_near(RenderSettings(), scene.robust_radius)
    data = CullData.from_scene(scene)
    chunks = ChunkedCull(data)
    base = default_camera(scene, 320, 180)
    centre = 0.5 * (scene.robust_bounds[0] + scene.robust_bounds[1])
    dist = float(np.linalg.norm(base.center - centre))
    for factor, azimuth in ((1.0, 0.0), (0.3, 40.0), (0.1, 200.0)):
        cam = base.with_pose(orbit(centre, dist * factor, azimuth, 20.0))
        anchored = anchored_camera(cam, scene.anchor)
        idx, z = cull_visible(data, anchored, near)
        for compiled in ([False, True] if cull_kernel.installed() else [False]):
            chunks.compiled = compiled
            np.testing.assert_array_equal(keys_order(chunks.visible_keys(anchored, near)),
                                          depth_sort(z, idx))
        for projection in ("fisheye", "equirectangular"):
            lcam = anchored_camera(retarget(cam, projection), scene.anchor)
            p_cam = to_camera(scene.relative_means, lcam)
            kept = np.flatnonzero(lens_cull(p_cam, scene.opacities, lcam, near))
            reach = splat_reach(scene.scales[kept].max(axis=1), scene.opacities[kept])
            depth, keep = lens_order(p_cam, kept, reach, lcam)
            np.testing.assert_array_equal(keys_order(lens_visible_keys(chunks, lcam, near)),
                                          depth_sort(depth, keep))


def test_compiled_cull_is_loaded_in_the_background_from_the_second_view(monkeypatch):
    """Default policy: the first view starts nothing (a one-frame render never imports
    numba); from the second view on the kernel is requested; views take the NumPy path until
    it has loaded and the compiled one after; "off" never takes it; an unknown policy is
    refused."""
    _need_kernel()
    loaded = cull_kernel.kernel()
    points, max_scale, opac = _clustered(5000, 7)
    camera = _cameras()[1]
    requests = []
    monkeypatch.setattr(cull_kernel, "request", lambda: requests.append(1))
    monkeypatch.setattr(cull_kernel, "kernel", lambda wait=False: None)  # not loaded yet
    chunks = ChunkedCull(CullData(points, max_scale, opac), chunk=16, group=4)
    first = np.sort(chunks.visible_keys(camera, 0.05))
    assert chunks.last_path == "numpy" and not requests
    second = np.sort(chunks.visible_keys(camera, 0.05))
    assert chunks.last_path == "numpy" and len(requests) == 1
    monkeypatch.setattr(cull_kernel, "kernel", lambda wait=False: loaded)  # now loaded
    third = np.sort(chunks.visible_keys(camera, 0.05))
    assert chunks.last_path == "compiled"
    np.testing.assert_array_equal(first, second)
    np.testing.assert_array_equal(first, third)
    cull_kernel.set_policy("off")
    try:
        chunks.visible_keys(camera, 0.05)
        assert chunks.last_path == "numpy"
    finally:
        cull_kernel.set_policy("auto")
    with pytest.raises(ValueError, match="policy must be one of auto, off, wait, got 'fast'"):
        cull_kernel.set_policy("fast")


def test_kernel_loader_hands_out_the_registered_modules_all_or_none(monkeypatch):
    """The loader imports no kernel module of its own: it hands out the ``KERNELS`` of the
    modules registered with it, once all of them are loaded.  A module registered after the load
    was requested gets a load of its own, and until that one is ready :func:`kernel` gives None
    (the NumPy paths); nothing registered gives None too."""
    import sys
    import threading
    import types

    gate = threading.Event()

    def fake(name, names, warm_up):
        mod = types.ModuleType(name)
        mod.KERNELS, mod.warm_up = names, warm_up
        for k in names:
            setattr(mod, k, f"{name}.{k}")
        monkeypatch.setitem(sys.modules, name, mod)

    fake("splatgl_test_kernels_a", ("a_pass", "a2_pass"), lambda: None)
    fake("splatgl_test_kernels_b", ("b_pass",), gate.wait)
    for name, value in (("_modules", []), ("_loads", {}), ("_requested", False), ("_merged", None)):
        monkeypatch.setattr(cull_kernel, name, value)
    monkeypatch.setattr(cull_kernel, "installed", lambda: True)
    try:
        assert cull_kernel.kernel(wait=True) is None  # nothing registered
        cull_kernel.register("splatgl_test_kernels_a")
        cull_kernel.register("splatgl_test_kernels_a")  # once only
        assert cull_kernel._modules == ["splatgl_test_kernels_a"]
        got = cull_kernel.kernel(wait=True)
        assert vars(got) == {"a_pass": "splatgl_test_kernels_a.a_pass",
                             "a2_pass": "splatgl_test_kernels_a.a2_pass"}
        cull_kernel.register("splatgl_test_kernels_b")  # after the request: loads at once
        assert cull_kernel._loads["splatgl_test_kernels_b"] is not cull_kernel._loads["splatgl_test_kernels_a"]
        assert cull_kernel.kernel() is None  # b still compiling (held at the gate)
        gate.set()
        got = cull_kernel.kernel(wait=True)
        assert vars(got) == {"a_pass": "splatgl_test_kernels_a.a_pass",
                             "a2_pass": "splatgl_test_kernels_a.a2_pass",
                             "b_pass": "splatgl_test_kernels_b.b_pass"}
        assert cull_kernel.kernel() is got
    finally:
        gate.set()


def test_compiled_cull_leaves_undecidable_peak_bounds_to_numpy(monkeypatch):
    """Faint splats centred on pixel centres have a peak bound equal to their float32 opacity,
    within 6e-8 of 1/255: too close for the compiled float64 bound to call (exp may differ from
    NumPy's in the last bits), so it hands them to NumPy's bound and the keys stay the float64
    cull's.  With no room for such rows the view takes the NumPy path instead."""
    _need_kernel()
    rng = np.random.default_rng(5)
    camera = Camera(64, 48, 100.0, 100.0, 32.5, 24.5, np.eye(4))
    # background: clustered splats in front of the camera; then three faint ones on centres
    points, max_scale, opac = _clustered(3000, 11)
    points[:, 2] += 12.0
    o = np.float32(1 / 255)
    while float(o) < 1 / 255:
        o = np.nextafter(o, np.float32(1))
    edge = np.array([[0.0, 0.0, 5.0], [0.1, -0.1, 10.0], [-0.2, 0.2, 20.0]], np.float32)
    points = np.concatenate([points, edge])
    max_scale = np.concatenate([max_scale, rng.uniform(0.001, 0.01, 3).astype(np.float32)])
    opac = np.concatenate([opac, np.full(3, o, np.float32)])
    want = _want_keys(points, max_scale, opac, camera, 0.05)
    assert np.isin(np.arange(3000, 3003), want.view(np.uint32)[0::2]).all()  # kept, just
    chunks = ChunkedCull(CullData(points, max_scale, opac), chunk=16, group=4)
    chunks.compiled = True
    np.testing.assert_array_equal(np.sort(chunks.visible_keys(camera, 0.05)), want)
    assert chunks.last_path == "compiled"
    monkeypatch.setattr(cull_chunks, "UNSURE_ROWS", 0)  # no room: every such row overflows
    np.testing.assert_array_equal(np.sort(chunks.visible_keys(camera, 0.05)), want)
    assert chunks.last_path == "numpy"


@pytest.mark.parametrize("compiled", [False, True])
@pytest.mark.parametrize("cam_index", range(5))
def test_rows_keys_cull_a_subset_as_the_float64_cull_does(cam_index, compiled):
    """The cull of a LOD cut's rows (a sorted subset, culled in place): the keys of the rows
    the float64 cull keeps among them, with the row as the index, compiled or gathered."""
    from splatgl.order.chunks import rows_keys

    kern = None
    if compiled:
        _need_kernel()
        kern = cull_kernel.kernel()
    points, max_scale, opac = _clustered(20_000, 40 + cam_index)
    camera = _cameras()[cam_index]
    rows = np.flatnonzero(np.random.default_rng(cam_index).random(20_000) < 0.4)
    want = _want_keys(points[rows], max_scale[rows], opac[rows], camera, 0.05)
    words = want.view(np.uint32).reshape(-1, 2)
    words[:, 0] = rows[words[:, 0]]  # positions in the subset -> rows
    out = np.empty(rows.size, np.uint64)
    got = rows_keys(CullData(points, max_scale, opac), rows, camera, 0.05, False, camera.scale,
                    kern, out)
    assert 0 < want.size < rows.size and np.shares_memory(got, out)
    np.testing.assert_array_equal(np.sort(got), np.sort(want))


def test_compiled_cull_in_a_forked_child(monkeypatch):
    """A process forked after the helper thread started (a fork-based worker pool) culls on
    two threads too, instead of waiting for a thread it does not have."""
    import multiprocessing as mp

    _need_kernel()
    monkeypatch.setattr(cull_chunks, "SPLIT_ROWS", 1)
    points, max_scale, opac = _clustered(20_000, 23)
    camera = _cameras()[1]
    chunks = ChunkedCull(CullData(points, max_scale, opac), chunk=32, group=8)
    chunks.compiled = True
    want = np.sort(chunks.visible_keys(camera, 0.05))  # the helper thread now exists
    assert cull_kernel.helper() is not None
    ctx = mp.get_context("fork")
    with ctx.Pool(1) as pool:
        got = pool.apply_async(_child_keys, (chunks, camera)).get(timeout=60)
    np.testing.assert_array_equal(got, want)


def _child_keys(chunks, camera):
    keys = np.sort(chunks.visible_keys(camera, 0.05))
    assert chunks.last_path == "compiled"
    return keys
