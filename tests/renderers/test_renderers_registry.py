"""The renderer interface and registry (issue 39 item 3): every renderer behind one protocol,
made through one table, and one place that answers "can renderer R draw this"."""

from __future__ import annotations

import dataclasses
import re
from pathlib import Path

import numpy as np
import pytest

from helpers import SURFELS, random_scene
from splatgl import Renderer
from splatgl.cameras.camera import Camera
from splatgl.cameras.view import View
from splatgl.errors import CameraError, SplatglError
from splatgl.scene.settings import Order, RendererKind, RenderSettings
from splatgl.output.layers import Layer, with_layers
from splatgl.renderers import options, registry

PACKAGE = Path(__file__).resolve().parents[2] / "splatgl"
CAMERA = Camera.from_fov(24, 16, 60.0)


def test_every_kind_has_one_entry_and_the_default_comes_first():
    assert list(registry.RENDERERS) == list(RendererKind)
    assert registry.names()[0] == "quad"
    assert registry.names(interactive=True) == ["quad", "tile", "cpu"]


@pytest.mark.parametrize("kind", list(RendererKind))
def test_each_renderer_follows_the_protocol(ctx, kind):
    if not registry.installed(kind):
        pytest.skip(f"{kind.value} needs {registry.entry(kind).needs[0]}")
    scene, settings = random_scene(20, 3, center=(0.0, 0.0, 4.0), spread=0.5), RenderSettings()
    made = registry.make(kind, scene, settings, ctx)
    try:
        assert isinstance(made, registry.FrameRenderer) and made.kind is kind
        view = View.of(CAMERA, settings, scene)
        assert made.supports(view) is None
        out = made.render(view)
        assert out.rgba.shape == (16, 24, 4)
        times = made.last_times
        assert isinstance(times, registry.StageTimes)
        assert times.total >= times.ordering >= 0.0 and times.drawing >= 0.0
        assert times.summary(scene.count).startswith("splats ")
    finally:
        made.release()


def test_the_one_check_answers_for_every_renderer():
    surfels = random_scene(4, **SURFELS)
    panorama = Camera.equirectangular(8, 4).model
    assert registry.refusal("tile", model=panorama) == (
        "the tile renderer cannot draw equirectangular images; use --renderer quad, reference "
        "or cpu")
    with pytest.raises(CameraError):
        registry.check("tile", model=panorama)
    assert registry.refusal("quad", model=panorama) is None
    if registry.installed("cpu"):
        assert registry.refusal("cpu", scene=surfels) == (
            "--renderer cpu draws 3DGS splats; this scene holds 2DGS surfels (use --renderer "
            "quad or tile)")
        assert "not normal" in registry.refusal("cpu", layers=with_layers(Layer.NORMAL))
        assert "--under" in registry.refusal("cpu", under=True)
    per_pixel = RenderSettings(order=Order.PER_PIXEL)
    assert [k.value for k in RendererKind if registry.refusal(k, settings=per_pixel) is None
            and registry.installed(k)] == [k for k in ("tile", "reference")]
    # a lens camera draws no surfels, whichever renderer asks
    for kind in ("quad", "tile", "reference"):
        with pytest.raises(CameraError, match="fisheye cameras render 3DGS scenes only"):
            registry.check(kind, scene=surfels, model=Camera.fisheye(8, 8, 180).model)


def test_what_each_renderer_reads_is_its_options_fields():
    """The entry declares no list of settings: its options class's fields are what it reads,
    and the readers of a setting (and so the refusal of one nobody in play reads) follow."""
    assert {k: e.options for k, e in registry.RENDERERS.items()} == {
        RendererKind.QUAD: options.QuadOptions, RendererKind.TILE: options.TileOptions,
        RendererKind.REFERENCE: options.ReferenceRendererOptions,
        RendererKind.CPU: options.CpuOptions}
    assert options.DRAWN == {"background", "near", "antialias", "sh_degree", "transform"}
    for e in registry.RENDERERS.values():
        assert set(options.field_names(e.options)) == options.DRAWN | e.reads
    assert registry.RENDERERS[RendererKind.TILE].reads == {"gpu_storage", "sort_key", "order",
                                                          "order_window"}
    assert registry.RENDERERS[RendererKind.CPU].reads == frozenset()
    assert registry.readers("extent") == {RendererKind.QUAD}
    assert registry.readers("gpu_storage") == {RendererKind.QUAD, RendererKind.TILE}
    assert registry.readers("background") == set(RendererKind)
    assert set(registry.OPTIONS) == set().union(*(e.reads for e in registry.RENDERERS.values()))
    assert set(registry.OPTIONS) | options.DRAWN == {f.name for f in dataclasses.fields(RenderSettings)}
    with pytest.raises(SplatglError, match="--extent square applies to the quad renderer only"):
        registry.check_settings(RenderSettings(extent="square"), "tile")


def test_options_fields_are_the_settings_own_declared_once():
    """Each options class's fields take their type and default from RenderSettings (declared
    there once, named by options.reads; issue 39 item 8), so a default changed there is the
    renderers' default too."""
    settings = {f.name: f for f in dataclasses.fields(RenderSettings)}
    for cls in (options.DrawOptions, options.QuadOptions, options.TileOptions, options.CpuOptions,
                options.ReferenceRendererOptions):
        for f in dataclasses.fields(cls):
            assert (f.type, f.default) == (settings[f.name].type, settings[f.name].default), f.name
        assert cls() == cls.of(RenderSettings())
    assert "precision:" not in Path(options.__file__).read_text()   # not declared again there


def test_options_for_takes_each_renderers_part_of_the_settings_in_one_place():
    from splatgl.scene.emulation import Emulation

    asked = RenderSettings(precision="rgba16f", order=Order.PER_PIXEL, order_window=8,
                           background=(0.5, 0.5, 0.5), sh_degree=1, sort_key="gpu")
    assert registry.options_for("tile", asked) == options.TileOptions(
        background=(0.5, 0.5, 0.5), sh_degree=1, sort_key="gpu", order=Order.PER_PIXEL,
        order_window=8)
    quad = registry.options_for("quad", RenderSettings(precision="rgba16f", near=0.5))
    assert quad == options.QuadOptions(precision="rgba16f", near=0.5)
    assert registry.options_for("quad", quad) is quad        # already the quad path's own
    ref = registry.options_for("reference", RenderSettings(convention="gsplat",
                                                           emulation=Emulation(extent="fixed")))
    assert ref.reference.compat.value == "gsplat" and ref.reference.emulation.extent == "fixed"
    # what it would draw by other rules is refused there, as the constructors did
    with pytest.raises(SplatglError, match="--convention gsplat applies to the NumPy reference only"):
        registry.options_for("quad", RenderSettings(convention="gsplat"))
    with pytest.raises(SplatglError, match="--order per-pixel is drawn by"):
        registry.options_for("cpu", RenderSettings(order=Order.PER_PIXEL))
    with pytest.raises(SplatglError, match="--sort bucket16 applies to the quad renderer only"):
        registry.options_for("tile", RenderSettings(sort_key="bucket16"))
    with pytest.raises(TypeError, match="the tile renderer takes TileOptions"):
        registry.options_for("tile", quad)
    # a View is made from a renderer's options as from the settings
    scene = random_scene(20, 3, center=(0.0, 0.0, 4.0), spread=0.5)
    assert View.of(CAMERA, quad, scene).key == View.of(CAMERA, RenderSettings(near=0.5), scene).key


def _recording(cls: type, read: set) -> type:
    """A subclass of options class ``cls`` that notes each field read into ``read``."""
    names = set(options.field_names(cls))

    class Recording(cls):
        def __getattribute__(self, name):
            if name in names:
                read.add(name)
            return object.__getattribute__(self, name)

    return Recording


@pytest.mark.parametrize("kind", list(RendererKind))
def test_each_renderer_reads_exactly_its_options(ctx, kind):
    """Made and drawing two views, each renderer reads every field of its options (the View,
    made from them, reads the near plane and the scene transform) and nothing else: the
    options hold exactly the settings it reads."""
    if not registry.installed(kind):
        pytest.skip(f"{kind.value} needs {registry.entry(kind).needs[0]}")
    e, read = registry.entry(kind), set()
    values = {"order": Order.PER_PIXEL} if "order_window" in e.reads else {}  # its window's
    own = _recording(e.options, read)(**values)
    read.clear()                                    # what validating it read
    scene = random_scene(20, 3, center=(0.0, 0.0, 4.0), spread=0.5)
    made = registry.make(kind, scene, own, ctx)
    try:
        assert made.options is own
        for camera in (CAMERA, Camera.from_fov(24, 16, 50.0)):    # a second view re-sorts
            made.render(View.of(camera, made.options, scene))
    finally:
        made.release()
    assert read == set(options.field_names(e.options))


def test_the_constructors_take_the_settings_too(ctx):
    """``CpuRenderer(scene, settings)`` (docs/api.md) and the others: the settings become the
    renderer's own options in the constructor."""
    from splatgl.renderers.quad import QuadRenderer
    from splatgl.renderers.reference_renderer import ReferenceRenderer

    scene = random_scene(20, 3, center=(0.0, 0.0, 4.0), spread=0.5)
    quad = QuadRenderer(ctx, scene, RenderSettings(extent="square", order_window=8))
    try:
        assert quad.options == options.QuadOptions(extent="square")
    finally:
        quad.release()
    assert ReferenceRenderer(scene, RenderSettings(convention="gsplat")).options == (
        options.ReferenceRendererOptions(convention="gsplat"))
    with pytest.raises(SplatglError, match="--convention gsplat applies to the NumPy reference"):
        QuadRenderer(ctx, scene, RenderSettings(convention="gsplat"))


def test_the_api_keeps_each_renderer_by_its_own_options(ctx):
    """A setting only the quad path reads makes a new quad renderer and keeps the tile one
    (keyed by the whole settings, each change made every renderer anew)."""
    scene = random_scene(20, 3, center=(0.0, 0.0, 4.0), spread=0.5)
    with Renderer(ctx) as r:
        quad, tile = (r.renderer_for(scene, RenderSettings(), k) for k in ("quad", "tile"))
        ref = r.renderer_for(scene, RenderSettings(), "reference")
        changed = RenderSettings(precision="rgba16f", extent="square")
        assert r.renderer_for(scene, changed, "tile") is tile
        assert r.renderer_for(scene, changed, "reference") is ref
        assert r.renderer_for(scene, changed, "quad") is not quad
        assert r.renderer_for(scene, RenderSettings(order_window=8), "quad") is quad
        assert r.renderer_for(scene, RenderSettings(background=(1.0, 0.0, 0.0)), "tile") is not tile
        assert isinstance(tile.options, options.TileOptions)


@pytest.mark.parametrize("early_stop", ["auto", "off"])
def test_a_renderer_draws_the_same_frame_after_another_context_was_current(early_stop):
    """A Renderer's cached path drew on whatever context was current: after ``splatgl.render``
    or a second Renderer, its next frame raised "cannot map the buffer" (early termination's
    coverage read) or, with early_stop off, came back nearly empty (alpha mean 5e-41)."""
    import splatgl

    scene = random_scene(200, 1, center=(0.0, 0.0, 4.0), spread=0.5)
    settings = RenderSettings(early_stop=early_stop)
    with Renderer() as r:
        first = r.render(scene, CAMERA, settings)
        splatgl.render(scene, CAMERA, settings)         # its own context, made current
        with Renderer() as other:
            other.render(scene, CAMERA, settings)
        again = r.render(scene, CAMERA, settings)
    assert first[..., 3].max() > 0.1
    np.testing.assert_array_equal(again, first)


def test_a_timed_frame_follows_a_warm_up_where_the_entry_says_so():
    assert [k.value for k, e in registry.RENDERERS.items() if not e.warms_up] == ["reference"]
    for module in ("commands/compare.py", "measure/bench/popping_bench.py"):
        assert "if kind is not RendererKind.REFERENCE" not in (PACKAGE / module).read_text()


def test_the_reference_through_the_api_needs_no_opengl_context(monkeypatch):
    """The NumPy reference and the CPU renderer are made through the registry like the others;
    no context is made for them (it was made for every Renderer)."""
    import splatgl.api as api

    def refuse():
        raise AssertionError("an OpenGL context was made")

    monkeypatch.setattr(api, "create_headless_context", refuse)
    scene = random_scene(20, 3, center=(0.0, 0.0, 4.0), spread=0.5)
    with Renderer() as r:
        rgba = r.render(scene, CAMERA, RenderSettings(), "reference")
        assert r.renderer_for(scene, RenderSettings(), "reference").last_times.total > 0.0
    assert rgba.shape == (16, 24, 4) and np.isfinite(rgba).all()


def test_few_modules_outside_the_registry_and_the_commands_name_a_renderer_kind():
    """Who names a renderer kind (beyond a renderer naming its own): the API's signatures, the
    viewer's quad fast path and its quad-against-tile difference view, the interactive drafts
    (the quad path, the CPU renderer; a streamed scene's drafts are the quad path's too), and the popping benchmark's named rows.  Defaults
    name DEFAULT_RENDERER; each renderer's image size limit is its entry's ``gl_limit``.
    ``--renderer auto``'s choice (renderers/auto.py) sits beside the registry."""
    naming = set()
    for path in PACKAGE.rglob("*.py"):
        rel = path.relative_to(PACKAGE).as_posix()
        if rel.startswith("commands/") or rel in ("renderers/registry.py", "renderers/auto.py"):
            continue
        text = path.read_text()
        own = re.search(r"^    kind = RendererKind\.(\w+)$", text, re.M)
        named = set(re.findall(r"RendererKind\.(QUAD|TILE|CPU|REFERENCE)", text))
        if named - ({own.group(1)} if own else set()):
            naming.add(rel)
    assert len(naming) <= 9, sorted(naming)     # 19 before the registry


def test_own_settings_puts_back_what_a_renderer_does_not_read():
    from splatgl.scene.emulation import Emulation

    asked = RenderSettings(extent="square", convention="gsplat", emulation=Emulation(extent="fixed"),
                           order=Order.PER_PIXEL, background=(0.5, 0.5, 0.5))
    tile = registry.own_settings(asked, "tile")
    assert tile == RenderSettings(order=Order.PER_PIXEL, background=(0.5, 0.5, 0.5))
    assert registry.own_settings(asked, "reference") == RenderSettings(
        convention="gsplat", emulation=Emulation(extent="fixed"), order=Order.PER_PIXEL,
        background=(0.5, 0.5, 0.5))
    plain = RenderSettings()
    assert registry.own_settings(plain, "cpu") is plain


@pytest.mark.parametrize("kind", list(RendererKind))
def test_render_takes_the_view_the_layers_and_the_geometry_under_in_that_order(kind):
    import inspect

    cls = registry.entry(kind).renderer_class()
    assert list(inspect.signature(cls.render).parameters)[:4] == ["self", "view", "layers", "under"]
