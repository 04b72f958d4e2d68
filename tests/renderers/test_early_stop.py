"""Early termination in the quad path (splatgl/renderers/early_stop.py): schedule, GPU passes against
their NumPy twins (splatgl/splatmath/early_stop.py), the accuracy bound against no stop and the reference, the batch hook."""

from __future__ import annotations

import dataclasses

import moderngl
import numpy as np
import pytest
from hypothesis import given, settings as hsettings, strategies as st

import splatgl.renderers.batches as batches_module
from splatgl.renderers import early_stop as es
from splatgl.splatmath import early_stop as stops
from splatgl.constants import ALPHA_MAX, T_MIN
from splatgl.measure.bench.probes import count_fragments
from splatgl.renderers.quad import QuadRenderer
from helpers import draw, view_for
from splatgl.api import default_camera
from splatgl.scene.splats import Scene, SplatKind
from splatgl.scene.settings import EarlyStop, Precision, Preprocess, RenderSettings
from splatgl.measure.stress.build import at_pixel, front_camera, splats

#: Weight a pixel may receive beyond the reference's stop (docs/early-stop.md): the reference
#: stops with T (1 - alpha) < T_MIN, alpha <= ALPHA_MAX, so T < T_MIN / (1 - ALPHA_MAX) = 0.01.
EXTRA_WEIGHT = T_MIN / (1.0 - ALPHA_MAX)
#: float32 blending slack of the GPU (one ulp per blend over ~1000 layers).
FLOAT_SLACK = 1e-4


def dense_scene(n: int = 8000, seed: int = 0, kind: SplatKind = SplatKind.GAUSSIAN_3D) -> Scene:
    """Overlapping opaque splats in a slab: most pixels saturate, many splats are hidden."""
    rng = np.random.default_rng(seed)
    ns = 2 if kind is SplatKind.SURFEL_2D else 3
    means = np.column_stack([rng.uniform(-2.5, 2.5, n), rng.uniform(-1.8, 1.8, n), rng.uniform(0, 1.5, n)])
    return Scene(means, rng.normal(size=(n, 4)), rng.normal(-2.2, 0.3, (n, ns)),
                 rng.normal(3.0, 1.0, n), rng.normal(0, 0.5, (n, 1, 3)), kind)


def _settings(**change) -> RenderSettings:
    return dataclasses.replace(RenderSettings(), **change)


@given(st.integers(0, 5_000_000), st.floats(1e-4, 1.0), st.floats(0.5, 3.0), st.integers(1, 10_000))
@hsettings(max_examples=200)
def test_batch_bounds_cover_the_order_in_bounded_increasing_batches(count, frac, growth, min_batch):
    b = es.batch_bounds(count, frac, growth, min_batch)
    assert b[0] == 0 and b[-1] == count
    steps = np.diff(b)
    assert (steps > 0).all() and (steps <= es.MAX_BATCH).all()
    p = es.plain_bounds(count)
    assert p[0] == 0 and p[-1] == count and (np.diff(p) <= es.MAX_BATCH).all()


def test_twins_on_a_known_mask():
    alpha = np.zeros((20, 35), np.float32)
    alpha[:16, :16] = 1.0                     # tile (0, 0) fully stopped
    alpha[:16, 16:32] = 1.0
    alpha[3, 20] = np.float32(1.0 - 2e-4)     # T = 2e-4 >= T_MIN: block (1, 0) of tile (0, 1) open
    alpha[16:, 32:] = 1.0                     # partial edge tile (1, 2): all its in-image pixels
    tiles = stops.stop_tiles(alpha)
    assert (tiles == es.TILE_STOPPED).tolist() == [[True, False, False], [False, False, True]]
    assert tiles[0, 1] == es.TILE_STOPPED & ~(1 << 1)   # every block of tile (0, 1) but one
    # Blocks past the image edge count as stopped: tile (0, 2) keeps its first block column
    # (x 32..34) open, tile (1, 0) its first block row (y 16..19).
    assert tiles[0, 2] == 0xEEEE and tiles[1, 0] == 0xFFF0
    np.testing.assert_array_equal(stops.unpack_blocks(tiles), stops.stop_blocks(alpha))
    lo = np.array([[1.0, 1.0], [1.0, 1.0], [-9.0, 2.0], [33.0, 17.0], [40.0, 3.0],
                   [24.0, 8.0], [20.0, 2.0], [17.0, 4.0]])
    hi = np.array([[14.0, 15.0], [20.5, 15.0], [-0.5, 5.0], [34.0, 19.9], [50.0, 4.0],
                   [31.9, 15.0], [22.0, 5.0], [19.9, 9.0]])
    keep = stops.occlusion_cull(lo, hi, tiles, 35, 20)
    # on a stopped tile only / reaches the open block of tile (0, 1) / off-image / stopped edge tile / off-image /
    # stopped blocks of tile (0, 1) / its open block / the blocks beside it
    assert keep.tolist() == [False, True, False, False, False, False, True, False]


def _gpu_passes(ctx, alpha: np.ndarray):
    from splatgl.gl.shaders import ProgramCache

    h, w = alpha.shape
    rgba = np.zeros((h, w, 4), np.float32)
    rgba[..., 3] = alpha
    tex = ctx.texture((w, h), 4, rgba.tobytes(), dtype="f4")
    depth = ctx.depth_renderbuffer((w, h))
    mask_fbo = ctx.framebuffer(depth_attachment=depth)
    mask_fbo.use()
    mask_fbo.depth_mask = True
    mask_fbo.clear(depth=1.0)
    programs = ProgramCache(ctx)
    passes = batches_module.EarlyStopPasses(ctx, programs)
    passes.prepare(1, [0, 1], w, h)
    ctx.enable(moderngl.DEPTH_TEST)
    ctx.depth_func = "<"
    passes.mark(tex, mask_fbo)
    ctx.disable(moderngl.DEPTH_TEST)
    marked = np.frombuffer(mask_fbo.read(components=1, attachment=-1, dtype="f4"), np.float32).reshape(h, w) == 0.0
    passes.reduce_tiles(tex, w, h)
    ctx.memory_barrier()
    gw, gh = -(-w // 16), -(-h // 16)
    tiles = np.frombuffer(passes.tiles.read(size=4 * gw * gh), np.uint32).reshape(gh, gw)
    passes.release()
    programs.release()
    for obj in (mask_fbo, depth, tex):
        obj.release()
    ctx.detect_framebuffer(0).use()
    return marked, tiles


def test_mark_and_tile_passes_match_their_twins(ctx):
    rng = np.random.default_rng(3)
    h, w = 37, 70
    t = np.where(rng.random((h, w)) < 0.9, rng.uniform(0, 2e-4, (h, w)), rng.uniform(0, 1, (h, w)))
    t[:16, 16:48] = 5e-5                       # two tiles certainly stopped
    alpha = (1.0 - t).astype(np.float32)
    marked, tiles = _gpu_passes(ctx, alpha)
    np.testing.assert_array_equal(marked, stops.stop_mask(alpha))
    np.testing.assert_array_equal(tiles, stops.stop_tiles(alpha))
    assert tiles[0, 1] == tiles[0, 2] == es.TILE_STOPPED
    assert 0 < np.count_nonzero((tiles != 0) & (tiles != es.TILE_STOPPED)), "partly stopped tiles"



@pytest.mark.parametrize("preprocess", [Preprocess.COMPUTE, Preprocess.VERTEX])
def test_occlusion_cull_matches_its_twin(ctx, monkeypatch, preprocess):
    """Two batches: the GPU's tiles and survivors of batch 2 equal the twins' applied to the
    alpha read back after batch 1 and the rectangles of the pre-pass."""
    scene = dense_scene()
    cam = front_camera(4.0, 50.0, 96, 64, target=(0.0, 0.0, 0.5))
    quad = QuadRenderer(ctx, scene, _settings(early_stop=True, preprocess=Preprocess.COMPUTE))
    n = len(quad.order(view_for(quad, cam)))
    split = n // 3
    monkeypatch.setattr(batches_module, "batch_bounds", lambda count, *_: [0, split, count])
    after_first = {}

    def hook(done, total):
        if done == split:
            after_first["alpha"] = quad.target(view_for(quad, cam)).read()[..., 3]

    draw(quad, cam, on_batch=hook).rgba
    alpha = after_first["alpha"]
    tiles = stops.stop_tiles(alpha)
    gpu_tiles = np.frombuffer(quad.batches.passes.tiles.read(size=4 * tiles.size), np.uint32)
    np.testing.assert_array_equal(gpu_tiles.reshape(tiles.shape), tiles)
    assert (tiles == es.TILE_STOPPED).mean() > 0.2, "the scene must stop some tiles for the test to mean anything"
    prepared = np.frombuffer(quad.gpu.prepared.buf.read(size=64 * n), np.float32).reshape(n, 4, 4)
    mean, a1, a2 = prepared[:, 0, :2], prepared[:, 0, 2:], prepared[:, 1, :2]
    half = np.abs(a1) + np.abs(a2)
    visible = prepared[:, 3, 2] != 0
    lo, hi = mean - half, mean + half
    first = stops.occlusion_cull(lo[:split], hi[:split], None, cam.width, cam.height) & visible[:split]
    second = stops.occlusion_cull(lo[split:], hi[split:], tiles, cam.width, cam.height) & visible[split:]
    n_cmd_first = -(-split // es.SEGMENT)
    n_cmd = n_cmd_first + -(-(n - split) // es.SEGMENT)
    stop = quad.batches.passes
    assert stop.survivor_count(n_cmd) - stop.survivor_count(n_cmd_first) == int(second.sum())
    expected_culled = n - int(first.sum() + second.sum())
    assert quad.batches.occlusion_culled == expected_culled > 0.1 * n
    quad.release()
    if preprocess is Preprocess.VERTEX:  # the vertex path's cull computes the same rectangles
        quad = QuadRenderer(ctx, scene, _settings(early_stop=True, preprocess=preprocess))
        draw(quad, cam).rgba
        assert quad.batches.occlusion_culled == expected_culled
        quad.release()


def test_quads_over_too_many_tiles_skip_the_walk(ctx, monkeypatch):
    """A quad over more than OCCLUSION_MAX_TILES tiles is kept without walking them (llvmpipe's
    loop limit): with the bound at 1 tile only single-tile quads are culled, the GPU count
    equals the twin's, and the image is unchanged (culled quads lie on stopped pixels only)."""
    import splatgl.constants as constants

    scene = dense_scene()
    cam = front_camera(4.0, 50.0, 96, 64, target=(0.0, 0.0, 0.5))
    base = QuadRenderer(ctx, scene, _settings(early_stop=True))
    full = draw(base, cam).rgba
    culled_full = base.batches.occlusion_culled
    base.release()
    monkeypatch.setattr(constants, "OCCLUSION_MAX_TILES", 1)
    capped = QuadRenderer(ctx, scene, _settings(early_stop=True))
    image = draw(capped, cam).rgba
    culled = capped.batches.occlusion_culled
    capped.release()
    assert 0 < culled < culled_full
    np.testing.assert_array_equal(image, full)
    lo, hi = np.array([[0.0, 0.0], [0.0, 0.0]]), np.array([[15.0, 15.0], [40.0, 15.0]])
    tiles = np.full((4, 6), es.TILE_STOPPED, np.uint32)   # every tile stopped
    assert stops.occlusion_cull(lo, hi, tiles, 96, 64).tolist() == [False, True]


def _bound_check(on, off, name):
    """|on - off| <= EXTRA_WEIGHT max|c - bg| per pixel (colour below 1 here), and no pixel
    moves away from what no-stop gives by more than the dropped tail can weigh."""
    diff = np.abs(on - off)
    assert diff.max() <= EXTRA_WEIGHT * max(1.0, float(off[..., :3].max())) + FLOAT_SLACK, name


@pytest.mark.parametrize("kind,preprocess", [(SplatKind.GAUSSIAN_3D, Preprocess.COMPUTE),
                                             (SplatKind.GAUSSIAN_3D, Preprocess.VERTEX),
                                             (SplatKind.SURFEL_2D, Preprocess.VERTEX)])
def test_on_stays_within_the_bound_of_off_and_culls(gl_renderer, monkeypatch, kind, preprocess):
    # A fine schedule (about 14 batches): many batch boundaries for the bound to hold across.
    monkeypatch.setattr(batches_module, "batch_bounds", lambda count, *_: es.batch_bounds(count, 1 / 64, 1.35))
    scene = dense_scene(kind=kind)
    cam = front_camera(4.0, 50.0, 128, 96, target=(0.0, 0.0, 0.5))
    on_settings = _settings(early_stop=True, preprocess=preprocess, background=(0.2, 0.4, 0.9))
    off_settings = dataclasses.replace(on_settings, early_stop=False)
    on = gl_renderer.render_layers(scene, cam, on_settings)
    off = gl_renderer.render_layers(scene, cam, off_settings)
    _bound_check(on.rgba, off.rgba, f"{kind.value} {preprocess.value}")
    # Depth uses the same weights: bounded by the extra weight times the farthest depth.
    assert np.abs(on.depth - off.depth).max() <= EXTRA_WEIGHT * 2.5 * 4.0 + 1e-3
    quad = gl_renderer.renderer_for(scene, on_settings)
    assert quad.last_times.occlusion_culled > 0.05 * quad.last_times.drawn  # 7-40% measured


def test_rasterised_count_includes_the_fragments_early_tests_reject(ctx, monkeypatch):
    """One batch: nothing is marked, so on rasterises and shades exactly off's fragments.  Two
    batches: the depth test rejects fragments after rasterising them (shaded < rasterised), and
    the occlusion cull only removes quads (rasterised < off's), with the same image."""
    scene = dense_scene()
    cam = front_camera(4.0, 50.0, 96, 64, target=(0.0, 0.0, 0.5))
    off = QuadRenderer(ctx, scene, _settings(early_stop=False))
    on = QuadRenderer(ctx, scene, _settings(early_stop=True))
    n = len(on.order(view_for(on, cam)))
    off_shaded, off_kept = count_fragments(off, view_for(off, cam))
    assert count_fragments(off, view_for(off, cam), rasterised=True) == (off_shaded, off_kept)
    monkeypatch.setattr(batches_module, "batch_bounds", lambda count, *_: [0, count])
    view = view_for(on, cam)
    assert count_fragments(on, view) == count_fragments(on, view, rasterised=True) == (off_shaded, off_kept)
    monkeypatch.setattr(batches_module, "batch_bounds", lambda count, *_: [0, n // 3, count])
    image = draw(on, cam).rgba
    shaded, kept = count_fragments(on, view_for(on, cam))
    rasterised, kept_late = count_fragments(on, view_for(on, cam), rasterised=True)
    np.testing.assert_array_equal(on.target(cam).read(), image)  # the late-test variant's image
    assert shaded < 0.8 * rasterised and rasterised < off_shaded
    assert kept < kept_late <= off_kept  # the late variant also counts rejected kept fragments
    off.release()
    on.release()


def test_half_precision_target_is_unchanged(gl_renderer):
    """rgba16f stores A = 1 before T < 1e-4 is representable; blending then adds exactly 0."""
    scene = dense_scene()
    cam = front_camera(4.0, 50.0, 96, 64, target=(0.0, 0.0, 0.5))
    on = gl_renderer.render(scene, cam, _settings(early_stop=True, precision=Precision.RGBA16F))
    off = gl_renderer.render(scene, cam, _settings(early_stop=False, precision=Precision.RGBA16F))
    np.testing.assert_array_equal(on, off)


def test_no_stop_error_against_reference_never_grows(gl_renderer, shared_scenes):
    """The accuracy claim on a real scene: per pixel, the stopped image is no farther from the
    reference than the unstopped one (up to float slack), so PSNR cannot drop."""
    from helpers import shared_file
    from splatgl.formats import load_scene
    from splatgl.measure.evaluation.metrics import image_errors
    from splatgl.api import render_reference_rgba

    scene = load_scene(shared_file(shared_scenes, "ply/donut_sh0.ply"))
    cam = default_camera(scene, 160, 96)
    ref = render_reference_rgba(scene, cam, RenderSettings())
    on = gl_renderer.render(scene, cam, _settings(early_stop=True))
    off = gl_renderer.render(scene, cam, _settings(early_stop=False))
    assert (np.abs(on - ref) <= np.abs(off - ref) + FLOAT_SLACK).all()
    assert image_errors(on, ref).psnr >= image_errors(off, ref).psnr - 0.01


@pytest.mark.parametrize("early_stop", [True, False])
def test_batch_hook_reports_progress_and_can_interrupt(gl_renderer, monkeypatch, early_stop):
    scene = dense_scene(3000)
    cam = front_camera(4.0, 50.0, 64, 48, target=(0.0, 0.0, 0.5))
    settings = _settings(early_stop=early_stop)
    quad = gl_renderer.renderer_for(scene, settings)
    monkeypatch.setattr(es, "MAX_BATCH", 700)
    monkeypatch.setattr(batches_module, "plain_bounds", lambda n, m=None: es.plain_bounds(n, 700))
    seen = []
    expected = draw(quad, cam, on_batch=lambda done, total: seen.append((done, total))).rgba
    total = seen[-1][1]
    assert seen[-1][0] == total and len(seen) >= 2
    assert all(a[0] < b[0] for a, b in zip(seen, seen[1:]))

    def stop(done, total):
        raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        draw(quad, cam, on_batch=stop).rgba
    assert not quad.ctx.error.startswith("GL_INVALID")
    np.testing.assert_array_equal(draw(quad, cam).rgba, expected)


def test_reference_counts_blended_fragments():
    """Eight stacked splats of opacity 0.8 centred on a pixel: T = 0.2^k, and the sixth would
    take T to 6.4e-5 < 1e-4, so exactly five are blended there."""
    from splatgl.reference import render_reference

    cam = front_camera(5.0, 60.0, 32, 32)
    means = [at_pixel(cam, 16.5, 16.5, 5.0 + 0.01 * i) for i in range(8)]
    scene = splats(means, np.full((8, 3), 0.05), opacities=np.full(8, 0.8))
    ref = render_reference(scene, cam)
    assert ref.n_blended[16, 16] == 5
    assert ref.n_blended[0, 0] == 0
    # Away from the centre, alpha < 1/255 stops counting before the opacity stop does.
    assert 0 < ref.n_blended[16, 18] <= 8


def test_renderer_progress_reaches_the_quad_draw(gl_renderer, monkeypatch):
    """``Renderer.render(..., progress=cb)`` (what the commands pass) hears the quad path's
    batches, and the image is the one drawn without a listener."""
    scene = dense_scene(3000)
    cam = front_camera(4.0, 50.0, 64, 48, target=(0.0, 0.0, 0.5))
    settings = _settings(early_stop=False)
    monkeypatch.setattr(batches_module, "plain_bounds", lambda n, m=None: es.plain_bounds(n, 700))
    plain = gl_renderer.render(scene, cam, settings)
    heard = []
    img = gl_renderer.render(scene, cam, settings, progress=lambda d, t, what: heard.append((d, t, what)))
    assert len(heard) >= 2 and heard[-1][0] == heard[-1][1]
    assert {w for _, _, w in heard} == {"quad: drawing splats"}
    np.testing.assert_array_equal(img, plain)


@pytest.mark.parametrize("kind,preprocess", [(SplatKind.GAUSSIAN_3D, Preprocess.COMPUTE),
                                             (SplatKind.GAUSSIAN_3D, Preprocess.VERTEX),
                                             (SplatKind.SURFEL_2D, Preprocess.VERTEX)])
def test_coverage_estimate_matches_its_twin_and_the_fragments(ctx, kind, preprocess):
    """``--early-stop auto``'s estimate (coverage.comp) equals its twin on the pre-pass's
    quads (float32 sums: 1e-4 relative) and predicts the fragments a plain draw shades (each
    quad's area against its pixel-centre count: within 3% over 8000 quads)."""
    scene = dense_scene(kind=kind)
    cam = front_camera(4.0, 50.0, 128, 96, target=(0.0, 0.0, 0.5))
    auto = QuadRenderer(ctx, scene, _settings(early_stop="auto", preprocess=preprocess))
    draw(auto, cam).rgba
    estimate = auto.batches.fragments_estimate
    if kind is SplatKind.SURFEL_2D:   # the twin: the surfel boxes (clamped to the image)
        from splatgl.splatmath.project import to_camera
        from splatgl.splatmath.surfel import surfel_bounds, surfel_screen

        screen = surfel_screen(scene.means, scene.rotations, scene.scales, cam)
        boxes = surfel_bounds(screen, scene.opacities, cam, view_for(auto, cam).near)
        shown = boxes.visible & (to_camera(scene.means, cam)[:, 2] > view_for(auto, cam).near)
        twin = float((4.0 * boxes.half[:, 0] * boxes.half[:, 1])[shown].sum())
        # GPU float32 boxes and sums against the float64 twin: 1e-3 relative (measured 4e-7).
        assert estimate == pytest.approx(twin, rel=1e-3) and estimate > 0
        auto.release()
        return
    plain = QuadRenderer(ctx, scene, _settings(early_stop=False, preprocess=preprocess))
    off_shaded, _ = count_fragments(plain, view_for(plain, cam))
    assert estimate == pytest.approx(off_shaded, rel=0.03)
    if preprocess is Preprocess.COMPUTE:   # the twin, from the pre-pass's quads
        n = plain.prepare(view_for(plain, cam))[0]
        p = np.frombuffer(plain.gpu.prepared.buf.read(size=64 * n), np.float32).reshape(n, 4, 4)
        visible = p[:, 3, 2] != 0
        mean, a1, a2 = p[visible, 0, :2], p[visible, 0, 2:], p[visible, 1, :2]
        half = np.abs(a1) + np.abs(a2)
        area = 4.0 * np.abs(a1[:, 0] * a2[:, 1] - a1[:, 1] * a2[:, 0])
        twin = stops.coverage(mean - half, mean + half, area, cam.width, cam.height)
        assert estimate == pytest.approx(twin, rel=1e-4)
    auto.release()
    plain.release()


def test_auto_batches_only_views_of_large_quads_over_an_overdrawn_image(ctx, monkeypatch):
    """AUTO draws exactly what OFF draws below either threshold and what ON draws above both
    (the rule of a software rasteriser; on a hardware GPU AUTO is ON: test_renderer_auto.py)."""
    monkeypatch.setenv("SPLATGL_DEVICE_CLASS", "software")
    scene = dense_scene()
    cam = front_camera(4.0, 50.0, 96, 64, target=(0.0, 0.0, 0.5))
    images = {}
    for mode in ("on", "off"):
        r = QuadRenderer(ctx, scene, _settings(early_stop=mode))
        images[mode] = draw(r, cam).rgba
        assert r.batches.batched is (mode == "on") and (r.batches.fragments_estimate > 0) is (mode == "on")
        r.release()
    auto = QuadRenderer(ctx, scene, _settings(early_stop="auto"))
    draw(auto, cam).rgba
    estimate = auto.batches.fragments_estimate
    per_pixel, per_quad = estimate / (cam.width * cam.height), estimate / auto.last_times.drawn
    assert per_pixel > 2.0 and per_quad > 2.0, "the dense scene overdraws"
    for pixel_min, quad_min, batched in ((per_pixel * 1.01, 0.0, False), (0.0, per_quad * 1.01, False),
                                         (per_pixel * 0.99, per_quad * 0.99, True)):
        monkeypatch.setattr(batches_module, "EARLY_STOP_MIN_OVERDRAW", pixel_min)
        monkeypatch.setattr(batches_module, "EARLY_STOP_MIN_QUAD_FRAGMENTS", quad_min)
        image = draw(auto, cam).rgba
        assert auto.batches.batched is batched and auto.last_times.batched is batched
        assert auto.last_times.batches == (3 if batched else 1)
        np.testing.assert_array_equal(image, images["on" if batched else "off"])
    # Quads this large take the fine schedule (about 8 batches) once the bar is below them.
    monkeypatch.setattr(batches_module, "EARLY_STOP_FINE_QUAD_FRAGMENTS", per_quad * 0.99)
    image = draw(auto, cam).rgba
    drawn = auto.last_times.drawn
    assert auto.last_times.batches == len(es.batch_bounds(drawn, *es.FINE_SCHEDULE)) - 1 > 3
    _bound_check(image, images["off"], "fine schedule")
    auto.release()


def test_settings_read_booleans_and_names_as_modes():
    from splatgl.scene.settings import EarlyStop

    assert RenderSettings().early_stop is EarlyStop.AUTO
    assert _settings(early_stop=True).early_stop is EarlyStop.ON
    assert _settings(early_stop=False).early_stop is EarlyStop.OFF
    assert _settings(early_stop="off").early_stop is EarlyStop.OFF
    with pytest.raises(ValueError):
        _settings(early_stop="sometimes")



@pytest.mark.parametrize("preprocess", [Preprocess.COMPUTE, Preprocess.VERTEX])
def test_survivors_buffer_growing_between_frames_rebuilds_its_vertex_array(ctx, monkeypatch, preprocess):
    """A plain frame of every splat (the order buffer grows), a batched frame of few, then a
    batched frame of many: only the survivors buffer grows (released and made anew).  The
    driver may hand the new buffer the old one's GL name (NVIDIA does; llvmpipe does not), and
    the frame must not draw through the cached vertex array of the released buffer: NVIDIA's
    driver crashed in render_indirect there.  The name's reuse is forced by renaming the cached
    entry; the image must equal a fresh renderer's."""
    scene = dense_scene()
    near = front_camera(4.0, 50.0, 96, 64, target=(0.0, 0.0, 0.5))
    aside = front_camera(4.0, 50.0, 96, 64, target=(5.0, 0.0, 0.5))   # the scene at the edge
    quad = QuadRenderer(ctx, scene, _settings(early_stop=True, preprocess=preprocess))
    fresh = QuadRenderer(ctx, scene, _settings(early_stop=True, preprocess=preprocess))
    try:
        assert 0 < len(quad.order(view_for(quad, aside))) < len(quad.order(view_for(quad, near))) // 2
        monkeypatch.setattr(quad.batches, "mode", EarlyStop.OFF)
        draw(quad, near).rgba                                      # the order buffer at its largest
        monkeypatch.setattr(quad.batches, "mode", EarlyStop.ON)
        draw(quad, aside).rgba                                     # survivors: few
        small = quad.batches.passes.survivors
        vaos = quad.gpu._vaos
        real_grow = quad.batches.passes._grow

        def grow_reusing_the_name(name, size):       # as a driver that reuses names would
            old = getattr(quad.batches.passes, name)
            buf = real_grow(name, size)
            if name == "survivors" and buf is not old:
                for key in [k for k in vaos if k[1] == old.glo]:
                    vaos[(key[0], buf.glo)] = vaos.pop(key)
            return buf

        monkeypatch.setattr(quad.batches.passes, "_grow", grow_reusing_the_name)
        got = draw(quad, near).rgba
        assert quad.batches.passes.survivors is not small       # it grew
        np.testing.assert_array_equal(got, draw(fresh, near).rgba)
    finally:
        quad.release()
        fresh.release()
