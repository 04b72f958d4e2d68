"""Early termination with the device-resident order (``--sort gpu --early-stop on|auto``;
splatgl/renderers/early_stop_device.py, shaders/stop_plan.comp), on llvmpipe.

shaders/stop_plan.comp makes the host's decisions (batched or not, the schedule, the batch
bounds) from the kept count on the device; frames are identical to early termination with the
CPU order, and a frame reads back only the image.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from splatgl.cameras.camera import Camera
from splatgl.cameras.poses import look_at
from splatgl.cameras.view import View
from splatgl.formats import load_scene
from splatgl.renderers import early_stop_device
from splatgl.renderers.early_stop import (COARSE_SCHEDULE, FINE_SCHEDULE, MAX_BATCH, SEGMENT,
                                          batch_bounds)
from splatgl.renderers.quad import QuadRenderer
from splatgl.scene.settings import EarlyStop, Preprocess, RenderSettings, SortKey
from splatgl.scene.splats import Scene

REPO = Path(__file__).resolve().parents[2]


def _scene(n: int, log_scale: tuple[float, float], seed: int = 7) -> Scene:
    rng = np.random.default_rng(seed)
    return Scene(rng.uniform(-1.2, 1.2, (n, 3)), rng.normal(size=(n, 4)),
                 rng.uniform(*log_scale, (n, 3)), rng.uniform(-1.0, 5.0, n),
                 rng.normal(0, 0.5, (n, 1, 3)))


#: (scene, camera distance): small splats far away (AUTO draws plainly, ON the coarse
#: schedule), large ones close (AUTO batches), very large ones (the fine schedule).
VIEWS = {"small": (dict(n=3000, log_scale=(-5.5, -3.5)), 4.0),
         "large": (dict(n=1500, log_scale=(-2.2, -1.2)), 3.0),
         "huge": (dict(n=400, log_scale=(-1.0, -0.3)), 2.2)}


def _render(ctx, scene, cam, key, mode, preprocess=Preprocess.COMPUTE):
    settings = RenderSettings(sort_key=key, early_stop=mode, preprocess=preprocess)
    r = QuadRenderer(ctx, scene, settings)
    try:
        view = View.of(cam, settings, scene)
        image = r.render(view).rgba
        info = (early_stop_device.plan_state(r.batches, r._device.slots) if key is SortKey.GPU
                else {"batched": r.batches.batched, "estimate": r.batches.fragments_estimate,
                      "count": r.last_times.drawn, "fine": r.batches._schedule is FINE_SCHEDULE})
        return image, info, r.last_times
    finally:
        r.release()


@pytest.mark.parametrize("preprocess", [Preprocess.COMPUTE, Preprocess.VERTEX])
@pytest.mark.parametrize("mode", [EarlyStop.ON, EarlyStop.AUTO])
@pytest.mark.parametrize("name", list(VIEWS))
def test_frames_and_decisions_are_the_cpu_orders(ctx, name, mode, preprocess):
    kwargs, dist = VIEWS[name]
    scene = _scene(**kwargs)
    cam = Camera.from_fov(96, 72, 55.0, look_at(np.array([0.3, -0.4, -dist]), np.zeros(3)))
    want, cpu, _ = _render(ctx, scene, cam, SortKey.EXACT, mode, preprocess)
    got, dev, times = _render(ctx, scene, cam, SortKey.GPU, mode, preprocess)
    assert want.any()
    np.testing.assert_array_equal(got, want)
    assert times.device_order and times.transfers.read_back == 96 * 72 * 16
    assert dev["batched"] == cpu["batched"] and int(round(dev["estimate"])) == cpu["estimate"]
    if cpu["batched"]:
        assert dev["fine"] == cpu["fine"]
        schedule = FINE_SCHEDULE if cpu["fine"] else COARSE_SCHEDULE
        assert dev["bounds"] == batch_bounds(cpu["count"], *schedule)
    else:
        assert dev["bounds"] == [0, cpu["count"]]
    expected = {("small", EarlyStop.AUTO): False}
    assert cpu["batched"] is expected.get((name, mode), True)
    assert cpu["fine"] is (name == "huge")


def test_demo_scene_is_identical_with_early_termination_on(ctx):
    scene = load_scene(REPO / "scenes" / "demo.ply")
    centre = scene.means.mean(axis=0)
    for d in (np.array([0.0, -0.5, -4.0]), np.array([0.3, 0.3, -0.6])):
        cam = Camera.from_fov(96, 72, 50.0, look_at(centre + d, centre))
        want, _, _ = _render(ctx, scene, cam, SortKey.EXACT, EarlyStop.ON)
        got, _, t = _render(ctx, scene, cam, SortKey.GPU, EarlyStop.ON)
        assert t.device_order and t.batched
        np.testing.assert_array_equal(got, want)


def test_a_moving_camera_reads_back_only_the_image(ctx):
    scene = _scene(**VIEWS["large"][0])
    settings = RenderSettings(sort_key=SortKey.GPU, early_stop=EarlyStop.ON)
    r = QuadRenderer(ctx, scene, settings)
    try:
        for k in range(3):
            cam = Camera.from_fov(80, 60, 55.0, look_at(np.array([0.3 + 0.1 * k, -0.4, -3.0]),
                                                        np.zeros(3)))
            r.render(View.of(cam, settings, scene))
            t = r.last_times
            assert t.device_order and t.batched, k
            assert t.transfers.read_back == 80 * 60 * 16, k
            assert t.transfers.uploaded <= 4096, k
    finally:
        r.release()


@pytest.mark.parametrize("slots", [1, 511, 4000, 70_001, 3_000_000, 9_000_000])
def test_the_host_issues_enough_batches_and_commands_for_any_count(slots):
    """max_batches and batch_groups bound batch_bounds for every count up to the slots."""
    n_b = early_stop_device.max_batches(slots)
    groups = early_stop_device.batch_groups(slots, n_b)
    counts = np.unique(np.concatenate([np.linspace(1, slots, 300).astype(int),
                                       np.arange(1, min(slots, 3000) + 1)]))
    for count in counts:
        for schedule in (COARSE_SCHEDULE, FINE_SCHEDULE):
            bounds = batch_bounds(int(count), *schedule)
            assert len(bounds) - 1 <= n_b, (count, schedule)
            for b, (s, e) in enumerate(zip(bounds[:-1], bounds[1:])):
                assert -(-(e - s) // SEGMENT) <= groups[b], (count, schedule, b)
    assert groups[0] * SEGMENT >= slots and max(groups[1:] or [0]) * SEGMENT <= MAX_BATCH + SEGMENT


@pytest.mark.parametrize("projection", ["orthographic", "fisheye", "equirectangular"])
def test_lens_views_are_identical_with_early_termination_on(ctx, projection):
    """The lens culls' order (a panorama's seam copies among its slots) batched alike."""
    from splatgl.cameras.framing import default_camera

    scene = _scene(**VIEWS["large"][0])
    cam = default_camera(scene, 96, 48, distance_scale=0.6, projection=projection)
    want, cpu, _ = _render(ctx, scene, cam, SortKey.EXACT, EarlyStop.ON)
    got, dev, t = _render(ctx, scene, cam, SortKey.GPU, EarlyStop.ON)
    assert want.any() and t.device_order and cpu["batched"] and dev["batched"]
    assert dev["bounds"][-1] == cpu["count"]
    np.testing.assert_array_equal(got, want)


def _cut_scene(cam: Camera, n_cut: int = 1500, n_opaque: int = 400, seed: int = 3) -> Scene:
    """Opaque splats over tiny faint ones whose brightest pixel centre is within 0.3% of 1/255
    (the peak-alpha cut: kept or culled they draw nothing): their kept count moves early
    termination's batch bounds unless the device keeps exactly the CPU's."""
    from splatgl.order.cull import peak_alpha_bound

    rng = np.random.default_rng(seed)
    m = 4 * n_cut
    uv = rng.uniform([-1.5, -1.5], [cam.width + 1.5, cam.height + 1.5], (m, 2))
    z = rng.uniform(2.0, 3.0, m)
    if cam.is_orthographic:
        p = np.stack([(uv[:, 0] - cam.cx) / cam.fx, (uv[:, 1] - cam.cy) / cam.fy, z], 1)
    else:
        p = np.stack([(uv[:, 0] - cam.cx) * z / cam.fx, (uv[:, 1] - cam.cy) * z / cam.fy, z], 1)
    log_scale = np.full((m, 3), np.log(1e-4))
    falloff = peak_alpha_bound(p, np.exp(log_scale[:, 0]), np.ones(m), cam)
    opac = (1 + rng.uniform(-3e-3, 3e-3, m)) / (255 * falloff)
    pick = np.flatnonzero(opac < 0.9)[:n_cut]
    assert pick.size == n_cut
    o = opac[pick]
    means = np.concatenate([p[pick], rng.uniform([-0.6, -0.5, 1.2], [0.6, 0.5, 1.5], (n_opaque, 3))
                            * ([1, 1, 1] if not cam.is_orthographic else [2.0, 2.0, 1.0])])
    scales = np.concatenate([log_scale[pick], rng.uniform(-3.5, -2.5, (n_opaque, 3))])
    logits = np.concatenate([np.log(o / (1 - o)), np.full(n_opaque, 4.0)])
    order = rng.permutation(n_cut + n_opaque)    # near-cut splats spread over every batch
    return Scene(means[order], rng.normal(size=(n_cut + n_opaque, 4)), scales[order],
                 logits[order], rng.normal(0, 0.5, (n_cut + n_opaque, 1, 3)))


@pytest.mark.parametrize("projection", ["pinhole", "orthographic"])
def test_splats_at_the_peak_alpha_cut_keep_the_batches_and_the_image(ctx, projection):
    """The device's float32 peak-alpha decision is the CPU's bit for bit (order_cull.comp's
    peak_keeps, splatgl.order.cull.peak_keeps): the same kept count, so the same batch bounds
    and the same image; with a band around the cut the device kept more and moved them."""
    cam = (Camera.from_fov(160, 120, 55.0) if projection == "pinhole"
           else Camera.orthographic(160, 120, 90.0))
    scene = _cut_scene(cam)
    want, cpu, _ = _render(ctx, scene, cam, SortKey.EXACT, EarlyStop.ON)
    got, dev, t = _render(ctx, scene, cam, SortKey.GPU, EarlyStop.ON)
    assert t.device_order and cpu["batched"] and 400 < cpu["count"] < scene.count
    assert dev["bounds"][-1] == cpu["count"]      # the kept counts (the band kept ~20% more)
    assert dev["bounds"] == batch_bounds(cpu["count"], *COARSE_SCHEDULE if not cpu["fine"]
                                         else FINE_SCHEDULE)
    np.testing.assert_array_equal(got, want)
