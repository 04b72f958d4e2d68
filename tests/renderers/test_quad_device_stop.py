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
