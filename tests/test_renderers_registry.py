"""The renderer interface and registry (issue 39 item 3): every renderer behind one protocol,
made through one table, and one place that answers "can renderer R draw this"."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from helpers import SURFELS, random_scene
from splatgl import Renderer
from splatgl.cameras.camera import Camera
from splatgl.cameras.view import View
from splatgl.errors import CameraError, SplatglError
from splatgl.model.settings import Order, RendererKind, RenderSettings
from splatgl.output.layers import Layer, with_layers
from splatgl.renderers import registry

PACKAGE = Path(__file__).resolve().parents[1] / "splatgl"
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


def test_what_each_renderer_reads_is_declared_in_its_entry():
    assert registry.readers("extent") == {RendererKind.QUAD}
    assert registry.readers("gpu_storage") == {RendererKind.QUAD, RendererKind.TILE}
    assert registry.readers("background") == set(RendererKind)
    assert set(registry.OPTIONS) == set().union(*(e.reads for e in registry.RENDERERS.values()))
    with pytest.raises(SplatglError, match="--extent square applies to the quad renderer only"):
        registry.check_settings(RenderSettings(extent="square"), "tile")


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
    (the quad path, the CPU renderer), and the popping benchmark's named rows.  Defaults
    name DEFAULT_RENDERER; each renderer's image size limit is its entry's ``gl_limit``."""
    naming = set()
    for path in PACKAGE.rglob("*.py"):
        rel = path.relative_to(PACKAGE).as_posix()
        if rel.startswith("commands/") or rel == "renderers/registry.py":
            continue
        text = path.read_text()
        own = re.search(r"^    kind = RendererKind\.(\w+)$", text, re.M)
        named = set(re.findall(r"RendererKind\.(QUAD|TILE|CPU|REFERENCE)", text))
        if named - ({own.group(1)} if own else set()):
            naming.add(rel)
    assert len(naming) <= 8, sorted(naming)     # 19 before the registry


def test_own_settings_puts_back_what_a_renderer_does_not_read():
    from splatgl.model.emulation import Emulation

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
