"""The CPU renderer (splatgl.renderers.cpu, ``--renderer cpu``) against the NumPy per-tile reference.

It runs the reference's algorithm in float32, so images are compared tightly: 2e-5 absolute on
the seeded scenes (measured worst 4e-6).  What may differ: the order of a few float32
operations in the projection, fused multiply-adds in the blending, and its own exp (relative
error below 3e-6, tested here), so a pixel whose splat sits exactly on the 1/255 or 1e-4
thresholds could differ by up to ~0.01; on the real scenes at 1280x720 one or two pixels in a
million do (biker: max 2.5e-3), hence their looser bound, with the mean and PSNR bounds
alongside.  The tile lists must be the reference's sorted keys, less only splats that cannot
reach alpha 1/255 anywhere in the tile.
"""

from __future__ import annotations

import dataclasses
import os

import numpy as np
import pytest

from helpers import IN_DEPTH, IN_VIEW, SURFELS, project, random_scene, shared_file, view_of
from splatgl.api import Renderer, default_camera, render
from splatgl.measure.bench.flight import Flight
from splatgl.cameras.camera import Camera
from splatgl.cameras.fisheye import Fisheye
from splatgl.cameras.opencv import OpenCV
from splatgl.cameras.registry import model_class
from splatgl.constants import ALPHA_MIN, TILE_SIZE
from splatgl.errors import SplatglError
from splatgl.formats import load_scene
from splatgl.scene.splats import Scene
from splatgl.scene.settings import Convention, RendererKind, RenderSettings
from splatgl.output.layers import BASE, Layer, with_layers
from splatgl.reference import emit_keys, render_reference, sort
from splatgl.reference.stages import tile_grid
from splatgl.renderers import cpu

pytest.importorskip("numba", reason="the CPU renderer needs numba (the fast extra)")
from splatgl.renderers import _cpu_raster as kernels  # noqa: E402

TOL = 2e-5
CAM = Camera.from_fov(160, 112, 60.0)      # not a multiple of 16 either way: partial tiles


def cpu_and_reference(scene, camera, settings=None, layers=BASE):
    settings = settings or RenderSettings()
    out = cpu.CpuRenderer(scene, settings).render(view_of(camera, scene, settings), layers)
    return out, render_reference(scene, camera, settings, np.float32)


def assert_close(got, want, tol=TOL):
    err = float(np.abs(np.asarray(got) - np.asarray(want)).max())
    assert err <= tol, f"max abs error {err:.3g} > {tol:.3g}"


# ------------------------------------------------------------------------------ images
@pytest.mark.parametrize("degree", [0, 1, 2, 3])
def test_image_and_depth_match_reference(degree):
    scene = random_scene(3000, 11 + degree, degree=degree, **IN_DEPTH)
    out, ref = cpu_and_reference(scene, CAM, layers=with_layers(Layer.DEPTH))
    assert out.rgba.shape == (CAM.height, CAM.width, 4) and out.rgba.dtype == np.float32
    assert_close(out.rgba, ref.rgba)
    assert_close(out.depth, ref.depth, 1e-5 * float(np.abs(ref.depth).max()))
    assert float(ref.alpha.max()) > 0.9, "the scene must cover the view"


@pytest.mark.parametrize("settings", [
    RenderSettings(antialias=True),
    RenderSettings(sh_degree=1, background=(0.2, 0.5, 1.0)),
    RenderSettings(near=3.5),
], ids=["antialias", "sh-cap-background", "near"])
def test_settings_match_reference(settings):
    scene = random_scene(2000, 5, degree=2, **IN_DEPTH)
    out, ref = cpu_and_reference(scene, CAM, settings)
    assert_close(out.rgba, ref.rgba)


def _model_camera(name):
    if name == "opencv":
        return Camera(128, 96, 90, 90, 64, 48, np.eye(4), OpenCV(k1=-0.35, k2=0.1, p1=0.01))
    fov = {"fisheye": 160.0, "fisheye-wide": 250.0, "fisheye-k": 180.0, "equirectangular": None,
           "orthographic": None}[name]
    cls = model_class(name.split("-")[0])
    camera = Camera.of_model(cls, 128, 128 if cls is Fisheye else 64, fov)
    if name == "fisheye-k":
        camera = dataclasses.replace(camera, model=Fisheye((0.05, -0.01, 0.002, 0.0)))
    return camera


@pytest.mark.parametrize("name", ["fisheye", "fisheye-wide", "fisheye-k", "opencv",
                                  "orthographic", "equirectangular"])
def test_other_camera_models_match_reference(name, monkeypatch):
    """Fisheye (past 180 degrees too, where the lens's distance rule culls), OpenCV
    distortion, orthographic and equirectangular cameras take the model's NumPy points,
    Jacobians and culling, the rest compiled; a panorama also its seam copies and the half-turn
    clip (splats here come close enough to be wider than the image).  Depth is the model's
    (the distance for a fisheye)."""
    # around the camera: some splats behind it, some inside the near plane, some past a
    # fisheye's angle limit, so each model's culling rule decides
    scene = random_scene(2000, 3, degree=1, **dict(IN_VIEW, center=(0.0, 0.0, 1.5),
                                                   spread=(2.0, 1.5, 2.0), log_scale=(-3.0, 0.5)))
    camera = _model_camera(name)
    from splatgl.renderers._cpu_stage1 import Stage1

    used = []
    real = Stage1.model
    monkeypatch.setattr(Stage1, "model", lambda self, *a: used.append(1) or real(self, *a))
    out, ref = cpu_and_reference(scene, camera, layers=with_layers(Layer.DEPTH))
    assert used == [1]
    assert_close(out.rgba, ref.rgba)
    assert_close(out.depth, ref.depth, 1e-5 * float(np.abs(ref.depth).max()))
    assert float(ref.alpha.max()) > 0.5


@pytest.mark.parametrize("name", ["pinhole", "pinhole-wide", "fisheye", "fisheye-wide",
                                  "fisheye-k", "opencv", "orthographic", "equirectangular"])
def test_it_projects_the_rows_its_views_cull_keeps_and_draws_every_rows_image(name, monkeypatch):
    """Only the rows the view's cull keeps are projected (:func:`splatgl.order.stage.cull_for`,
    the table the scene and level-of-detail orders use, in its conservative mode), and the
    image and depth are the ones every row gives, bit for bit.  Large splats all around the
    camera; through the wide pinhole some lie just past the image's edge, where the clamped
    EWA Jacobian's footprint reaches further than the splat's sphere
    (:func:`splatgl.order.stage.ewa_widening`: without it, 4 pixels differ)."""
    scene = random_scene(4000, 2, degree=1, **dict(IN_VIEW, center=(0.0, 0.0, 1.5),
                                                   spread=(3.0, 2.5, 3.0), log_scale=(-3.0, 0.8)))
    camera = {"pinhole": CAM, "pinhole-wide": Camera.from_fov(160, 112, 120.0)}.get(name)
    camera = camera or _model_camera(name)
    renderer = cpu.CpuRenderer(scene, RenderSettings())     # the kernels warmed up first
    kinds, real = [], cpu.cull_for
    monkeypatch.setattr(cpu, "cull_for", lambda view: kinds.append(view.frustum.kind) or real(view))
    view = view_of(camera, scene, RenderSettings())
    rgba, depth = renderer.draw(view, with_depth=True)
    assert kinds == [view.frustum.kind] and 0 < renderer.kept_rows(view).size < scene.count
    monkeypatch.setattr(renderer, "kept_rows", lambda view: None)
    every_rgba, every_depth = renderer.draw(view, with_depth=True)
    assert np.array_equal(rgba, every_rgba) and np.array_equal(depth, every_depth)


def test_a_fisheye_frame_cut_into_pieces_is_the_same_frame(monkeypatch):
    scene = random_scene(3000, 4, degree=2, **IN_VIEW)
    camera = _model_camera("fisheye")
    renderer = cpu.CpuRenderer(scene, RenderSettings())
    view = view_of(camera, scene, RenderSettings())
    whole, _ = renderer.draw(view)
    monkeypatch.setattr(cpu, "PART_SPLATS", 700)
    calls = []
    pieces, _ = renderer.draw(view, on_batch=lambda done, total: calls.append(done), bands=3)
    np.testing.assert_array_equal(pieces, whole)
    assert len(calls) >= 4 + 3 + 4     # projection parts, sort and bins, bands


def test_empty_scene_and_no_visible_splat_give_the_background():
    settings = RenderSettings(background=(0.1, 0.2, 0.3))
    behind = random_scene(50, 2, center=(0.0, 0.0, -5.0), spread=0.5)
    for scene in (random_scene(0, 1), behind):
        out = cpu.CpuRenderer(scene, settings).render(view_of(CAM, scene, settings))
        np.testing.assert_array_equal(out.rgba[..., :3], np.broadcast_to((0.1, 0.2, 0.3), out.rgba[..., :3].shape).astype(np.float32))
        assert not out.rgba[..., 3].any()


def test_non_finite_splats_are_culled_as_the_reference_culls_them():
    """NaN and infinite means, scales, colours and opacities, and a huge scale: no NaN in the
    image, and the reference's image (which culls non-finite rows) at the usual tolerance."""
    s = random_scene(2000, 3, degree=1, **IN_DEPTH)
    means, scales, sh, opacity = s.means.copy(), s.scales.copy(), s.sh.copy(), s.opacities.copy()
    means[0] = np.nan
    means[1, 2] = np.inf
    scales[2] = np.nan
    scales[3] = 1e30
    sh[4] = np.nan
    opacity[5] = np.nan
    bad = Scene.from_activated(means, s.rotations, scales, opacity, sh)
    out, ref = cpu_and_reference(bad, CAM)
    assert np.isfinite(out.rgba).all()
    assert_close(out.rgba, ref.rgba)


def test_api_and_renderer_cache_draw_the_same_pixels():
    scene = random_scene(1500, 8, degree=1, **IN_DEPTH)
    settings = RenderSettings()
    direct = cpu.CpuRenderer(scene, settings).render(view_of(CAM, scene, settings)).rgba
    with Renderer() as r:
        np.testing.assert_array_equal(r.render(scene, CAM, settings, RendererKind.CPU), direct)
        np.testing.assert_array_equal(r.render(scene, CAM, settings, "cpu"), direct)
        assert isinstance(r.renderer_for(scene, settings, RendererKind.CPU).last_times, cpu.CpuTimes)
        assert r.renderer_for(scene, settings, "cpu") is r.renderer_for(scene, settings, RendererKind.CPU)
    np.testing.assert_array_equal(render(scene, CAM, settings, "cpu"), direct)


def test_a_frame_cut_into_pieces_is_the_same_frame(monkeypatch):
    """``draw`` with ``on_batch``: projection and packing in parts, the blend in bands, a
    check before each piece; the pixels are those of one piece, and a check that raises
    abandons the frame."""
    scene = random_scene(5000, 6, degree=1, **IN_DEPTH)
    settings = RenderSettings()
    r = cpu.CpuRenderer(scene, settings)
    view = view_of(CAM, scene, settings)
    whole, whole_depth = r.draw(view, with_depth=True)
    monkeypatch.setattr(cpu, "PART_SPLATS", 1000)
    calls = []
    pieces, pieces_depth = r.draw(view, True, lambda done, total: calls.append((done, total)), 4)
    np.testing.assert_array_equal(pieces, whole)
    np.testing.assert_array_equal(pieces_depth, whole_depth)
    n_tiles = tile_grid(CAM.width, CAM.height)
    n_tiles = n_tiles[0] * n_tiles[1]
    drawn = r.last_times.drawn
    # projection parts, after it, after the sort, between packing parts, before each band
    assert len(calls) == 4 + 1 + 1 + (drawn - 1) // 1000 + 4
    assert [d for d, _ in calls[-4:]] == sorted(d for d, _ in calls[-4:]) and calls[-1][0] < n_tiles
    assert {t for _, t in calls} == {n_tiles}

    class Stop(Exception):
        pass

    def stop(done, total):
        raise Stop
    with pytest.raises(Stop):
        r.draw(view, False, stop, 4)


# ------------------------------------------------------------------------------ stages
def test_tile_lists_are_the_reference_keys_less_splats_that_cannot_blend():
    scene = random_scene(2500, 4, degree=0, **IN_DEPTH)
    settings = RenderSettings()
    r = cpu.CpuRenderer(scene, settings)
    view = view_of(CAM, scene, settings)
    mean2d, conic, opacity, reach, color, z, box, rect = r.stage1.pinhole(view, [(0, scene.count)])
    order = cpu.depth_order(z, rect)
    grid = tile_grid(CAM.width, CAM.height)
    starts, rows = kernels.bin_tiles(order, rect, grid[0], grid[0] * grid[1], 3)
    proj = project(scene, CAM, settings)
    keys, values = sort(*emit_keys(proj))
    tiles = (keys >> np.uint64(32)).astype(np.int64)
    dropped = 0
    for t in range(grid[0] * grid[1]):
        want = values[tiles == t]
        got = order[rows[starts[t]:starts[t + 1]]]
        kept = np.isin(want, got)
        np.testing.assert_array_equal(want[kept], got)         # same splats, same order
        dropped += int((~kept).sum())
        x0, y0 = (t % grid[0]) * TILE_SIZE, (t // grid[0]) * TILE_SIZE
        ys, xs = np.mgrid[y0:y0 + TILE_SIZE, x0:x0 + TILE_SIZE] + 0.5
        for i in want[~kept]:          # each dropped splat reaches < 1/255 in this tile
            a, b, c = proj.conic[i].astype(np.float64)
            dx, dy = xs - proj.mean2d[i, 0], ys - proj.mean2d[i, 1]
            alpha = proj.opacity[i] * np.exp(-0.5 * (a * dx * dx + c * dy * dy) - b * dx * dy)
            assert alpha.max() < ALPHA_MIN
    assert dropped > 1000, "the boxes must cut the lists down"


def test_box_and_row_spans_hold_every_pixel_the_reference_blends():
    """For thin, rotated and wide splats: each pixel with o exp(power) >= 1/255 (float64)
    lies in the splat's box; blending through the kernel equals blending every pixel."""
    rng = np.random.default_rng(7)
    n = 400
    scene = random_scene(n, 9, **dict(IN_DEPTH, log_scale=(-2.5, 1.2)))
    settings = RenderSettings()
    r = cpu.CpuRenderer(scene, settings)
    mean2d, conic, opacity, reach, color, z, box, rect = r.stage1.pinhole(view_of(CAM, scene, settings), [(0, scene.count)])
    kept = np.flatnonzero(rect[:, 1] > rect[:, 0])
    assert kept.size > 100
    for i in rng.choice(kept, 100, replace=False):
        a, b, c = conic[i].astype(np.float64)
        xs, ys = np.meshgrid(np.arange(-40, CAM.width + 40) + 0.5, np.arange(-40, CAM.height + 40) + 0.5)
        dx, dy = xs - mean2d[i, 0], ys - mean2d[i, 1]
        alpha = opacity[i] * np.exp(-0.5 * (a * dx * dx + c * dy * dy) - b * dx * dy)
        inside = alpha >= ALPHA_MIN
        px, py = np.floor(xs[inside]).astype(int), np.floor(ys[inside]).astype(int)
        on_image = (px >= 0) & (px < CAM.width) & (py >= 0) & (py < CAM.height)
        assert (px[on_image] >= box[i, 0]).all() and (px[on_image] < box[i, 1]).all()
        assert (py[on_image] >= box[i, 2]).all() and (py[on_image] < box[i, 3]).all()
        assert abs(reach[i] - 2.0 * np.log(255.0 * opacity[i])) < 1e-5 * max(1.0, reach[i])


def test_exp_is_accurate_over_the_powers_that_blend():
    """Below 3e-6 relative where a splat can blend (power >= ln(1/255): alpha = o exp(power)
    with o <= 1), and below 1e-4 down to the floor, where alpha stays far below 1/255."""
    for lo, bound in ((np.log(ALPHA_MIN), 3e-6), (kernels.POWER_FLOOR, 1e-4)):
        x = np.linspace(lo, 0.0, 2001).astype(np.float32)
        got = np.array([kernels._exp.py_func(v) for v in x], np.float64)
        assert float(np.max(np.abs(got / np.exp(x.astype(np.float64)) - 1.0))) < bound


def test_depth_order_is_nearest_first_with_ties_in_row_order():
    depth = np.array([3.0, 1.0, 3.0, 0.2, 0.5, 1.0, 7.0], np.float32)
    rect = np.ones((7, 4), np.int32)
    rect[:, 0] = 0
    rect[6, 1] = 0                     # an empty rectangle: not drawn
    np.testing.assert_array_equal(cpu.depth_order(depth, rect), [3, 4, 1, 5, 0, 2])


def test_tile_order_gives_every_tile_once():
    for n, threads in ((3600, 2), (7, 3), (1, 4)):
        order = cpu.tile_order(n, threads)
        np.testing.assert_array_equal(np.sort(order), np.arange(n))


# ------------------------------------------------------------------------------ refusals
@pytest.mark.parametrize("case, fragment", [
    ("surfels", "2DGS surfels"),
    ("gsplat", "--convention gsplat"),
    ("normal", "colour, alpha and depth only"),
])
def test_what_it_does_not_draw_is_refused_in_one_line(case, fragment):
    scene = random_scene(100, 1, **(SURFELS if case == "surfels" else IN_DEPTH))
    settings = RenderSettings(convention=Convention.GSPLAT) if case == "gsplat" else RenderSettings()
    with pytest.raises(SplatglError) as err:
        renderer = cpu.CpuRenderer(scene, settings)
        renderer.render(view_of(CAM, scene, settings), with_layers(Layer.NORMAL))
    assert fragment in str(err.value) and "\n" not in str(err.value)


def test_without_numba_it_says_which_extra(monkeypatch):
    from splatgl.renderers import registry

    monkeypatch.setattr(registry, "installed", lambda kind: False)
    with pytest.raises(SplatglError, match=r"pip install 'splatgl\[fast\]'"):
        cpu.CpuRenderer(random_scene(10, 1), RenderSettings())


_SIGNATURES = """
import json
from splatgl.renderers import cpu
from splatgl.api import Renderer, default_camera
from splatgl.cameras.registry import retarget
from splatgl.commands._common import demo_scene_path
from splatgl.formats import load_scene
from splatgl.scene.settings import RenderSettings
from splatgl.output.layers import Layer, with_layers

calls = []
cpu.prepare(lambda done, total, what: calls.append((done, total)))
names = ("project_pinhole", "project_model", "pack", "bin_tiles", "rasterize")
signatures = lambda: {n: sorted(map(str, getattr(cpu._LOADED, n).signatures)) for n in names}
ready = signatures()
scene, r = load_scene(demo_scene_path()), Renderer()
camera = default_camera(scene, 120, 90)
for settings in (RenderSettings(), RenderSettings(antialias=True, sh_degree=1, background=(0.2, 0.3, 0.4))):
    for projection in (None, "fisheye", "equirectangular", "orthographic", "opencv"):
        c = camera if projection is None else retarget(camera, projection)
        r.render_layers(scene, c, settings, "cpu", layers=with_layers(Layer.DEPTH))
print(json.dumps({"calls": calls, "ready": ready, "after": signatures()}))
"""


@pytest.mark.slow
def test_prepare_readies_every_kernel_signature_a_frame_calls():
    """prepare() (which the first renderer calls, and view before its window opens) leaves
    nothing for a frame to compile: numba compiles a signature per argument layout and
    read-only flag, about 25 s for the first on a fresh install, and a frame that met one
    unprepared stalled that long (the seam copies' writeable rows did).  A fresh process, so
    that what earlier tests compiled does not count; every camera model, depth, settings."""
    import json
    import subprocess
    import sys

    run = subprocess.run([sys.executable, "-c", _SIGNATURES], capture_output=True, text=True,
                         timeout=600, env=dict(os.environ, SPLATGL_PROGRESS="0"))
    assert run.returncode == 0, run.stderr[-3000:]
    got = json.loads(run.stdout.strip().splitlines()[-1])
    assert got["ready"] == got["after"]
    assert all(len(v) == 1 for v in got["ready"].values()), got["ready"]
    assert got["calls"] == [[0, 2], [1, 2], [2, 2]]


# ------------------------------------------------------------------------------ real scenes
@pytest.mark.slow
@pytest.mark.parametrize("name", ["ply/donut_sh0.ply", "compressed_ply/guitar.compressed.ply"])
def test_real_scenes_match_reference(shared_scenes, name):
    scene = load_scene(shared_file(shared_scenes, name))
    settings = RenderSettings()
    camera = Flight(scene, 480, 270).camera(0.3)       # the interactive flight's orbit
    out, ref = cpu_and_reference(scene, camera, settings, with_layers(Layer.DEPTH))
    diff = np.abs(out.rgba - ref.rgba)
    assert float(diff.max()) < 5e-3
    assert float(diff.mean()) < 1e-6
    mse = float(np.mean(diff[..., :3] ** 2))
    assert 10 * np.log10(1.0 / max(mse, 1e-30)) > 100.0
    assert int((ref.alpha > 0.5).sum()) > 2000, "the scene must be in view"
    rel = np.abs(out.depth - ref.depth) / max(float(np.abs(ref.depth).max()), 1e-6)
    assert float(rel.max()) < 1e-3


def test_cli_render_writes_the_cpu_image(tmp_path):
    from splatgl.cli import main
    from splatgl.imagefiles.images import read_image

    scene_path = tmp_path / "s.ply"
    from splatgl.formats import save_scene
    scene = random_scene(800, 2, degree=1, **IN_DEPTH)
    save_scene(scene_path, scene)
    out = tmp_path / "cpu.png"
    assert main(["render", str(scene_path), "--renderer", "cpu", "-o", str(out), "--width", "96",
                 "--height", "64", "--bit-depth", "16"]) == 0
    got = read_image(out)
    loaded = load_scene(scene_path)
    want = render_reference(loaded, default_camera(loaded, 96, 64), RenderSettings(), np.float32).rgba
    assert got.shape[:2] == (64, 96)
    assert float(np.abs(got[..., :3] - np.clip(want[..., :3], 0, 1)).max()) < 2.0 / 65535


def test_a_path_interrupted_while_the_kernels_compile_leaves_no_folder(tmp_path, monkeypatch):
    """render --path --renderer cpu prepares the kernels (half a minute on first use) before
    the output folder exists: Ctrl-C then leaves nothing (the folder used to be left, empty)."""
    from splatgl.cli import main

    calls = []

    def interrupted(progress=None):
        calls.append(1)
        raise KeyboardInterrupt

    monkeypatch.setattr(cpu, "prepare", interrupted)
    argv = ["render", "--renderer", "cpu", "--path", "orbit:3", "--width", "64", "--height", "48",
            "-o", str(tmp_path / "f")]
    assert main(argv) == 130 and calls == [1]
    assert list(tmp_path.iterdir()) == []


@pytest.mark.slow
@pytest.mark.parametrize("projection, fov", [("fisheye", 90.0), ("equirectangular", None)])
def test_real_scene_through_other_camera_models_matches_reference(shared_scenes, projection, fov):
    """donut through a fisheye and a panorama (the model's NumPy step, the compiled rest, the
    seam copies and half-turn clip), against the float32 reference; bounds as for the pinhole
    views above (measured 8e-7 and 9e-7 max here, 1522 and 5620 pixels covered)."""
    from splatgl.cameras.registry import retarget

    scene = load_scene(shared_file(shared_scenes, "ply/donut_sh0.ply"))
    camera = retarget(Flight(scene, 480, 240).camera(0.3), projection, fov)
    out, ref = cpu_and_reference(scene, camera, RenderSettings(), with_layers(Layer.DEPTH))
    diff = np.abs(out.rgba - ref.rgba)
    assert float(diff.max()) < 5e-3 and float(diff.mean()) < 1e-6
    assert int((ref.alpha > 0.5).sum()) > 200, "the scene must be in view"
    rel = np.abs(out.depth - ref.depth) / max(float(np.abs(ref.depth).max()), 1e-6)
    assert float(rel.max()) < 1e-3


@pytest.mark.parametrize("cached", [True, False])
def test_the_terminal_hears_of_a_compile_not_of_a_load(monkeypatch, cached):
    """Every cpu render on a terminal said 'preparing the CPU renderer (compiled on first use:
    about half a minute)', also when numba's cache held the kernels (a load of about 0.5 s)."""
    from splatgl.renderers import cpu

    heard = []
    monkeypatch.setattr(cpu, "_LOADED", None)
    monkeypatch.setattr(cpu, "_READY", False)
    monkeypatch.setattr(cpu, "kernels_ready", lambda: cached)
    monkeypatch.setattr(cpu, "default_progress", lambda: lambda *a: heard.append(a[2]))
    cpu.prepare()
    assert bool(heard) is not cached
