"""The tile renderer's device-resident order (``--sort gpu``, splatgl/renderers/tile_device.py,
issue 40): the scan, the key emission, the two radix-sort passes and the tile ranges on the GPU,
with images identical to the CPU order's, bit for bit; the overflow, seen in the image read
back, and the frame drawn again; nothing read back but the image."""

from __future__ import annotations

import dataclasses

import moderngl
import numpy as np
import pytest

from pathlib import Path

from helpers import (IN_DEPTH, SURFELS, SURFELS_POSE, draw, random_scene, shared_file, view_for)
from splatgl.cameras.camera import Camera
from splatgl.cameras.fisheye import Fisheye
from splatgl.cameras.opencv import OpenCV
from splatgl.cameras.poses import look_at, orbit
from splatgl.cli import main
from splatgl.constants import TILE_OVERFLOW_ALPHA
from splatgl.formats import load_scene
from splatgl.measure.stress import CASES
from splatgl.errors import SplatglError
from splatgl.scene.settings import Order, RenderSettings, SortKey
from splatgl.renderers import tile as tile_mod
from splatgl.renderers.tile import TileRenderer
from splatgl.renderers.tile_device import ranges_twin, scan_twin

CAM = Camera.from_fov(128, 96, 60.0)
REPO = Path(__file__).resolve().parents[2]
GPU = RenderSettings(sort_key=SortKey.GPU)


def _pair(ctx, scene, cam, settings=RenderSettings(), depth=False, capacity=None):
    """(CPU order's render, device order's render, the device renderer's retries)."""
    cpu = TileRenderer(ctx, scene, settings)
    dev = TileRenderer(ctx, scene, dataclasses.replace(settings, sort_key=SortKey.GPU))
    try:
        if capacity is not None:
            dev.device.capacity = capacity
        return draw(cpu, cam, depth=depth), draw(dev, cam, depth=depth), dev.device.retries
    finally:
        cpu.release()
        dev.release()


def _same(a, b, depth=False):
    np.testing.assert_array_equal(b.rgba, a.rgba)
    if depth:
        np.testing.assert_array_equal(b.depth, a.depth)


def test_scan_and_ranges_twins():
    counts = np.array([0, 3, 1, 0, 5], np.uint32)
    offsets, total = scan_twin(counts)
    assert offsets.tolist() == [0, 0, 3, 4, 4] and total == 9
    ranges = ranges_twin(np.array([0, 0, 2, 2, 2, 5], np.uint32), 6)
    assert ranges.tolist() == [[0, 2], [0, 0], [2, 5], [0, 0], [0, 0], [5, 6]]


@pytest.mark.parametrize("order", [Order.GLOBAL, Order.PER_PIXEL])
def test_device_stages_equal_the_cpu_order(ctx, order):
    """The sorted keys and splat indices and the ranges: the CPU order's (the twins), bit for
    bit.  The global order scans and emits the splats in depth order (the depth presort, ties
    by index): its offsets are the twin's scan of the counts in that order.  The per-pixel
    order emits in index order, as the CPU does: offsets and emitted keys are the CPU's."""
    scene = random_scene(3000, 7, degree=1, **IN_DEPTH)
    settings = RenderSettings(order=order)
    cpu = TileRenderer(ctx, scene, settings)
    dev = TileRenderer(ctx, scene, dataclasses.replace(settings, sort_key=SortKey.GPU))
    try:
        a = cpu.debug_stages(view_for(cpu, CAM))
        b = dev.debug_stages(view_for(dev, CAM))
        offsets = dev._bufs["OFFSETS"].read(scene.count * 4, np.uint32)
        z = dev._bufs["MEAN_DEPTH"].read(scene.count * 16, np.float32).reshape(-1, 4)[:, 2]
        presort = dev.device.presort
    finally:
        cpu.release()
        dev.release()
    assert len(a.keys) > 5000 and presort == (order is Order.GLOBAL)
    counts = a.tiles_touched.astype(np.uint32)
    if presort:
        depth_keys = np.where(counts > 0, z.view(np.uint32), np.uint32(0xFFFFFFFF))
        counts = counts[np.argsort(depth_keys, kind="stable")]
        assert len(b.emitted_keys) == 0          # not kept: the sort's keys are the tiles
    else:
        for field in ("emitted_keys", "emitted_values"):
            np.testing.assert_array_equal(getattr(b, field), getattr(a, field), err_msg=field)
    np.testing.assert_array_equal(offsets, scan_twin(counts)[0])
    for field in ("tiles_touched", "keys", "values", "ranges"):
        np.testing.assert_array_equal(getattr(b, field), getattr(a, field), err_msg=field)
    tiles = (a.keys >> np.uint64(32)).astype(np.uint32)
    np.testing.assert_array_equal(b.ranges, ranges_twin(tiles, len(a.ranges)))


@pytest.mark.parametrize("name, settings, camera", [
    ("default", RenderSettings(), CAM),
    ("aa_bg", RenderSettings(antialias=True, background=(0.2, 0.4, 0.9)), CAM),
    ("partial_tiles", RenderSettings(), Camera.from_fov(101, 77, 60.0)),
    ("orthographic", RenderSettings(near=0.5), Camera.orthographic(128, 96, 24.0)),
    ("per_pixel", RenderSettings(order=Order.PER_PIXEL), CAM),
    ("opencv", RenderSettings(), CAM.with_model(OpenCV(k1=-0.3, k2=0.05))),
    ("fisheye", RenderSettings(), CAM.with_model(Fisheye((0.05, -0.01, 0.002, 0.0)))),
])
def test_images_identical_to_the_cpu_order(ctx, name, settings, camera):
    scene = random_scene(2000, 5, degree=1, **IN_DEPTH)
    a, b, _ = _pair(ctx, scene, camera, settings, depth=True)
    assert a.rgba[..., 3].max() > 0.5
    _same(a, b, depth=True)


def test_surfels_identical_to_the_cpu_order(ctx):
    scene = random_scene(2000, 7, degree=1, **SURFELS)
    a, b, _ = _pair(ctx, scene, Camera.from_fov(128, 96, 60.0, SURFELS_POSE), depth=True)
    _same(a, b, depth=True)


def test_overflow_grows_the_buffers_and_draws_again(ctx):
    """A capacity far too small: the scan flags it on the device, the rasterizer marks every
    pixel's alpha TILE_OVERFLOW_ALPHA, the renderer sees it in the image it reads and only then
    reads the 8-byte status, grows the buffers to the total and a quarter and draws again: the
    image the CPU order's; the next frame needs no retry and reads the image alone."""
    scene = random_scene(2000, 3, degree=1, **IN_DEPTH)
    a, b, retries = _pair(ctx, scene, CAM, capacity=5)
    assert retries == 1
    _same(a, b)
    dev = TileRenderer(ctx, scene, GPU)
    image = CAM.width * CAM.height * 16
    try:
        need = dev.debug_stages(view_for(dev, CAM)).keys.size
        dev.device.capacity, dev.device.retries = 5, 0
        draw(dev, CAM)
        cap, first = dev.device.capacity, dev.last_times.transfers
        draw(dev, CAM)
        assert dev.device.retries == 1 and cap == need + need // 4   # grown, then kept
        assert first.read_back == 2 * image + 8 and dev.last_times.transfers.read_back == image
        rgba = dev._bufs["OUT_RGBA"].read(image, np.float32).reshape(-1, 4)
        dev.device.capacity = 5          # the overflowed frame's image: every alpha the mark
        dev._frame(view_for(dev, CAM))
        marked = dev._bufs["OUT_RGBA"].read(image, np.float32).reshape(-1, 4)
    finally:
        dev.release()
    assert (rgba[:, 3] >= 0).all() and (marked[:, 3] == TILE_OVERFLOW_ALPHA).all()


def test_the_capacity_stays_within_the_storage_block_limit(ctx):
    """The key buffers start and grow within GL_MAX_SHADER_STORAGE_BLOCK_SIZE (a 6M-splat scene
    on llvmpipe's 128 MiB would otherwise be refused before drawing); a frame whose keys
    exceed it is refused in one line, as the CPU order refuses it."""
    scene = random_scene(2000, 3, degree=1, **IN_DEPTH)
    dev = TileRenderer(ctx, scene, GPU)
    try:
        need = dev.debug_stages(view_for(dev, CAM)).keys.size
        dev.device.capacity, dev.device.max_block = 5, 8 * need      # exactly room for them
        a = draw(dev, CAM)
        assert dev.device.capacity == need
        dev.device.capacity, dev.device.max_block = 5, 8 * need - 8
        with pytest.raises(SplatglError, match=f"the tile renderer needs {need} keys "
                                               f"\\({8 * need} bytes\\), more than this OpenGL's "
                                               f"storage-block limit of {8 * need - 8} bytes"):
            draw(dev, CAM)
    finally:
        dev.release()
    assert a.rgba[..., 3].max() > 0.5


def test_long_lists_take_device_sized_passes(ctx, monkeypatch):
    """Tile lists longer than TILE_LIST_CHUNK: the passes come from the device (indirect), the
    image the CPU order's in as many passes."""
    monkeypatch.setattr(tile_mod, "TILE_LIST_CHUNK", 100)
    monkeypatch.setattr("splatgl.renderers.tile_device.TILE_LIST_CHUNK", 100)
    scene = random_scene(3000, 11, degree=1, **IN_DEPTH)
    a, b, _ = _pair(ctx, scene, CAM, RenderSettings(background=(0.2, 0.4, 0.9)), depth=True)
    _same(a, b, depth=True)


def test_emit_chunks_are_indirect_dispatches_sized_on_the_device(ctx, monkeypatch):
    """Rectangles over TILE_EMIT_CHUNK tiles: the scan writes a dispatch for each chunk the
    largest one needs (none for the rest); the keys and image are the CPU order's."""
    monkeypatch.setattr(tile_mod, "TILE_EMIT_CHUNK", 3)
    monkeypatch.setattr("splatgl.renderers.tile_device.TILE_EMIT_CHUNK", 3)
    scene = random_scene(2000, 3, degree=1, **IN_DEPTH)
    cpu, dev = TileRenderer(ctx, scene, RenderSettings()), TileRenderer(ctx, scene, GPU)
    try:
        a, b = cpu.debug_stages(view_for(cpu, CAM)), dev.debug_stages(view_for(dev, CAM))
        args = dev._bufs["STATE"].read(48 + 16 * 16, np.uint32)[12:].reshape(-1, 4)[:16]
        _same(draw(cpu, CAM), draw(dev, CAM))
    finally:
        cpu.release()
        dev.release()
    need = -(-int(a.tiles_touched.max()) // 3)
    assert 4 <= need < 16
    assert (args[:need, 0] > 0).all() and (args[need:, :3] == 0).all()
    np.testing.assert_array_equal(b.keys, a.keys)
    np.testing.assert_array_equal(b.values, a.values)


def test_gpu_shape_one_pass_one_band(ctx, monkeypatch):
    """On a GPU (no loop limit) the device order blends every list in one pass over the whole
    image: forced here on llvmpipe with a small chunk the CPU order needs passes for, the same
    image."""
    monkeypatch.setattr(tile_mod, "TILE_LIST_CHUNK", 100)
    monkeypatch.setattr(tile_mod, "RASTER_BAND_TILES", 8)
    scene = random_scene(3000, 11, degree=1, **IN_DEPTH)
    cpu = TileRenderer(ctx, scene, RenderSettings())
    dev = TileRenderer(ctx, scene, GPU)
    try:
        dev.device.software = False
        grid = (8, 6)
        assert dev.device.band(grid) == 6 and dev.device.slots(48)[1] == 1
        _same(draw(cpu, CAM, depth=True), draw(dev, CAM, depth=True), depth=True)
        # the 6 stage laps, colour and depth: no finishes between bands, no status word
        assert dev.last_times.transfers.syncs == 8
    finally:
        cpu.release()
        dev.release()


def test_moving_camera_and_empty_view(ctx):
    scene = random_scene(1500, 9, degree=1, **IN_DEPTH)
    cpu, dev = TileRenderer(ctx, scene, RenderSettings()), TileRenderer(ctx, scene, GPU)
    try:
        for azimuth in (170.0, 200.0, 20.0):   # the last looks away: no keys at all
            cam = Camera.from_fov(96, 80, 60.0, orbit(np.array([0.0, 0.0, 5.0]), 6.0, azimuth, 10.0))
            _same(draw(cpu, cam), draw(dev, cam))
    finally:
        cpu.release()
        dev.release()


def test_only_the_image_is_read_back(ctx, monkeypatch):
    """A frame of the device order, after the first: reads back the image, exactly, in one
    read (no status word: an overflow shows in the image), and uploads nothing (uniforms
    aside)."""
    scene = random_scene(2000, 5, degree=1, **IN_DEPTH)
    dev = TileRenderer(ctx, scene, GPU)
    reads, writes = [], []
    real_read, real_write = moderngl.Buffer.read, moderngl.Buffer.write

    def read(self, size=-1, offset=0, **kw):
        data = real_read(self, size, offset, **kw)
        reads.append(len(data))
        return data

    def write(self, data, offset=0):
        writes.append(len(memoryview(data).cast("B")))
        return real_write(self, data, offset)

    try:
        draw(dev, CAM)
        monkeypatch.setattr(moderngl.Buffer, "read", read)
        monkeypatch.setattr(moderngl.Buffer, "write", write)
        draw(dev, Camera.from_fov(128, 96, 60.0, orbit(np.array([0.0, 0.0, 5.0]), 6.0, 170.0, 10.0)))
    finally:
        monkeypatch.undo()
        dev.release()
    assert reads == [128 * 96 * 16] and writes == []
    moved = dev.last_times.transfers       # the same, as --timings and the bench report it
    assert dev.last_times.device_order and dev.last_times.n_keys is None
    assert moved.read_back == 128 * 96 * 16 and 0 < moved.uploaded <= 4096, moved


def test_cpu_order_transfers_are_counted(ctx):
    """The CPU order reads the counts and keys back and uploads offsets, keys and ranges: its
    --timings line says so (the device order's contrast)."""
    scene = random_scene(2000, 5, degree=1, **IN_DEPTH)
    cpu = TileRenderer(ctx, scene, RenderSettings())
    try:
        draw(cpu, CAM)
        moved, keys = cpu.last_times.transfers, cpu.last_times.n_keys
    finally:
        cpu.release()
    assert not cpu.last_times.device_order
    assert moved.read_back >= 128 * 96 * 16 + 4 * 2000 + 8 * keys
    assert moved.uploaded >= 4 * 2000 + 8 * keys


def test_bucket16_is_refused_by_the_tile_renderer(ctx):
    scene = random_scene(10, 1, degree=0, **IN_DEPTH)
    with pytest.raises(SplatglError, match="--sort bucket16 applies to the quad renderer only, "
                                           "not the tile renderer"):
        TileRenderer(ctx, scene, RenderSettings(sort_key=SortKey.BUCKET16))


def test_demo_scene_views_are_identical(ctx):
    scene = load_scene(REPO / "scenes" / "demo.ply")
    centre = scene.means.mean(axis=0)
    cpu, dev = TileRenderer(ctx, scene, RenderSettings()), TileRenderer(ctx, scene, GPU)
    try:
        for d in (np.array([0.0, -0.5, -4.0]), np.array([3.0, 0.2, 0.5]), np.array([0.3, 0.3, -0.6])):
            cam = Camera.from_fov(96, 72, 50.0, look_at(centre + d, centre))
            _same(draw(cpu, cam, depth=True), draw(dev, cam, depth=True), depth=True)
    finally:
        cpu.release()
        dev.release()


def test_a_shared_scene_is_identical(ctx, shared_scenes):
    scene = load_scene(shared_file(shared_scenes, "ply/donut_sh0.ply"))
    centre = np.median(scene.means, axis=0)
    radius = float(np.percentile(np.linalg.norm(scene.means - centre, axis=1), 90))
    for d in (np.array([0.0, -0.6, -2.0]), np.array([1.5, -0.3, 0.4])):
        cam = Camera.from_fov(128, 96, 50.0, look_at(centre + radius * d, centre))
        a, b, _ = _pair(ctx, scene, cam)
        assert a.rgba[..., 3].max() > 0.5
        _same(a, b)


_STRESS = [c for c in CASES if not c.slow and "tile" not in c.unsupported]


@pytest.mark.parametrize("case", _STRESS, ids=[c.name for c in _STRESS])
def test_stress_cases_are_identical(ctx, case):
    setup = case.build()
    a, b, _ = _pair(ctx, setup.scene, setup.camera, setup.settings, depth=True)
    _same(a, b, depth=True)


_SLOW_STRESS = [c for c in CASES if c.slow and "tile" not in c.unsupported]


@pytest.mark.slow
@pytest.mark.parametrize("case", _SLOW_STRESS, ids=[c.name for c in _SLOW_STRESS])
def test_slow_stress_cases_are_identical(ctx, case):
    """The 8192 x 8192 image: more tiles than one emit chunk's worth, bands, long lists."""
    setup = case.build()
    a, b, _ = _pair(ctx, setup.scene, setup.camera, setup.settings)
    _same(a, b)


def test_cli_renders_the_cpu_orders_image(tmp_path, capsys):
    """``render --renderer tile --sort gpu`` writes the image ``--sort exact`` does; its
    ``--timings`` line names the transfers: the image read back, nothing else."""
    demo = str(REPO / "scenes" / "demo.ply")
    args = ["render", demo, "--width", "48", "--height", "32", "--renderer", "tile"]
    assert main(args + ["-o", str(tmp_path / "a.png")]) == 0
    assert main(args + ["-o", str(tmp_path / "b.png"), "--sort", "gpu", "--timings"]) == 0
    line = [s for s in capsys.readouterr().out.splitlines() if s.startswith("timings")][0]
    assert f"read back {48 * 32 * 16:,} bytes" in line and "n_keys" not in line
    assert (tmp_path / "a.png").read_bytes() == (tmp_path / "b.png").read_bytes()


@pytest.mark.parametrize("renderer, message", [
    ("tile", "splatgl: error: --sort bucket16 applies to the quad renderer only, not the tile "
             "renderer (use --renderer quad)"),
])
def test_bucket16_on_the_tile_renderer_is_refused_in_one_line(tmp_path, capsys, renderer, message):
    rc = main(["render", str(REPO / "scenes" / "demo.ply"), "-o", str(tmp_path / "x.png"),
               "--renderer", renderer, "--sort", "bucket16"])
    out, err = capsys.readouterr()
    assert (rc, out, err) == (2, "", message + "\n")
    assert list(tmp_path.iterdir()) == []


def test_sort_gpu_on_the_cpu_renderer_names_both_readers(tmp_path, capsys):
    rc = main(["render", str(REPO / "scenes" / "demo.ply"), "-o", str(tmp_path / "x.png"),
               "--renderer", "cpu", "--sort", "gpu"])
    out, err = capsys.readouterr()
    assert (rc, out) == (2, "")
    assert err == ("splatgl: error: --sort gpu applies to the quad and tile renderers only, not "
                   "the cpu renderer, which would ignore it (use --renderer quad or tile, or "
                   "leave --sort out)\n")


def test_bench_tile_row_takes_its_part_of_sort():
    """``splatgl bench --sort bucket16``: the tile row draws its exact order (it used to ignore
    --sort, and refuses bucket16 now); ``--sort gpu``: the tile row runs the device order."""
    from splatgl.api import Renderer
    from splatgl.measure.bench.configs import BenchConfig, RowKind
    from splatgl.measure.bench.runner import _Runner
    scene = load_scene(REPO / "scenes" / "demo.ply")
    r = Renderer()
    try:
        for key, device in ((SortKey.BUCKET16, False), (SortKey.GPU, True)):
            row = BenchConfig("tile", "renderer", RowKind.TILE, RenderSettings(sort_key=key))
            run = _Runner(r, scene, row)
            assert (run.impl.device is not None) == device
    finally:
        r.close()


def test_the_viewer_cycle_skips_the_tile_renderer_for_bucket16():
    """The registry's check (the viewer's T cycle, api.Renderer) refuses what the tile renderer
    reads but cannot draw, instead of the renderer failing once made."""
    from splatgl.scene.settings import RendererKind
    from splatgl.renderers import registry
    why = registry.refusal(RendererKind.TILE, settings=RenderSettings(sort_key=SortKey.BUCKET16))
    assert why == ("--sort bucket16 applies to the quad renderer only, not the tile renderer "
                   "(use --renderer quad)")
    assert registry.refusal(RendererKind.TILE, settings=GPU) is None
    assert registry.refusal(RendererKind.QUAD, settings=RenderSettings(sort_key=SortKey.BUCKET16)) is None


def test_both_device_shapes_agree_on_the_global_order(ctx):
    """The depth presort (the global order's shape) and the general shape (two sorts of the
    emitted keys, the per-pixel order's) give the same image for the global order."""
    scene = random_scene(2000, 5, degree=1, **IN_DEPTH)
    images = []
    for presort in (True, False):
        dev = TileRenderer(ctx, scene, GPU)
        try:
            dev.device.presort = presort
            dev.programs = type(dev.programs)(ctx)
            images.append(draw(dev, CAM, depth=True))
        finally:
            dev.release()
    _same(images[0], images[1], depth=True)
