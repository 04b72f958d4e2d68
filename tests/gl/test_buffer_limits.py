"""Every GPU buffer that grows with the splats, the keys or the pixels goes through the one
driver-limit check (splatgl/gl/limits.py check_splat_buffer), refused in one line before it is
allocated: the per-view buffers (GrowableBuffer, whose slack never takes one past the limit),
the tile renderer's projections and key buffers in both orders, the quad path's device-order
cull rows and pre-pass output.  The limit is lowered as tests/gl/test_context.py lowers it
(MAX_BUFFER_BYTES: llvmpipe's limit)."""

from __future__ import annotations

import numpy as np
import pytest

from helpers import IN_DEPTH, REPO, draw, random_scene
from splatgl.cameras.camera import Camera
from splatgl.cli import main
from splatgl.errors import SplatglError
from splatgl.gl import limits
from splatgl.gl.buffers import GrowableBuffer
from splatgl.renderers.quad import QuadRenderer
from splatgl.renderers.tile import TileRenderer
from splatgl.scene.settings import Order, RenderSettings, SortKey

CAM = Camera.from_fov(32, 24, 60.0)


def _refusal(ctx, need: str, nbytes: int, what: str, limit: int,
             advice: str = limits.DERIVED_ADVICE) -> str:
    source = limits.buffer_limit(ctx)[1]
    return (f"{need} a GPU buffer of {nbytes:,} bytes ({what}), more than this OpenGL driver "
            f"allows in one ({limit:,} bytes, {source}); {advice}")


def _scene(n: int = 1000):
    """Splats about 6 pixels across in CAM's view: about 3 tile keys a splat."""
    return random_scene(n, 3, degree=0, **dict(IN_DEPTH, log_scale=(-1.0, 0.3)))


def test_growable_buffer_checks_each_growth_and_caps_its_slack(ctx, monkeypatch):
    monkeypatch.setattr(limits, "MAX_BUFFER_BYTES", 1000)
    buf = GrowableBuffer(ctx, slack=0.25, what="x, 8 bytes a tile key", stride=8, unit="tile keys")
    try:
        assert buf.ensure(900).size == 1000          # 1,125 with the slack: capped at the limit
        assert buf.ensure(1000).size == 1000 and not buf.grew
        with pytest.raises(SplatglError) as info:
            buf.ensure(1008)
        assert str(info.value) == _refusal(ctx, "126 tile keys need", 1008, "x, 8 bytes a tile key",
                                           1000)
        assert buf.buf.size == 1000                   # nothing released or allocated
        with pytest.raises(SplatglError) as info:
            GrowableBuffer(ctx).ensure(2000)          # unnamed: the bytes alone
        assert str(info.value) == _refusal(ctx, "it needs", 2000, "a per-view buffer", 1000)
    finally:
        buf.release()


@pytest.mark.parametrize("order, name, stride", [(Order.GLOBAL, "mean depth", 16),
                                                 (Order.PER_PIXEL, "peak", 48)])
def test_tile_projections_are_checked_before_anything_is_allocated(ctx, monkeypatch, order,
                                                                  name, stride):
    """The largest per-splat buffer of the tile renderer (the per-pixel order's peak
    coefficients, 48 bytes a splat; else 16) is refused before the scene is uploaded; at the
    limit the renderer is made."""
    scene = _scene()
    monkeypatch.setattr(limits, "MAX_BUFFER_BYTES", stride * 1000 - 1)
    with pytest.raises(SplatglError) as info:
        TileRenderer(ctx, scene, RenderSettings(order=order))
    assert str(info.value) == _refusal(
        ctx, "1,000 splats need", stride * 1000,
        f"the tile renderer's {name} buffer, {stride} bytes a splat", stride * 1000 - 1)
    monkeypatch.setattr(limits, "MAX_BUFFER_BYTES", stride * 1000)
    TileRenderer(ctx, scene, RenderSettings(order=order)).release()


@pytest.mark.parametrize("sort", [SortKey.EXACT, SortKey.GPU])
def test_tile_keys_past_the_limit_are_refused_in_both_orders(ctx, monkeypatch, sort):
    """The frame's keys (8 bytes each) one key short of the limit: the CPU order refuses them
    before growing its key buffer, the device order after the overflow shows in the image
    (its capacity never exceeds the limit): the same line.  At the limit both draw the
    unlimited image."""
    scene = _scene()
    settings = RenderSettings(sort_key=sort)
    r = TileRenderer(ctx, scene, RenderSettings())
    try:
        full = draw(r, CAM)
        keys = r.last_times.n_keys
    finally:
        r.release()
    assert keys > 2 * scene.count and 8 * keys > CAM.width * CAM.height * 16   # keys come last
    monkeypatch.setattr(limits, "MAX_BUFFER_BYTES", 8 * keys - 8)
    r = TileRenderer(ctx, scene, settings)
    try:
        with pytest.raises(SplatglError) as info:
            draw(r, CAM)
        monkeypatch.setattr(limits, "MAX_BUFFER_BYTES", 8 * keys)
        if r.device is not None:   # capped at the limit, grown to it after the overflow
            assert r.device.capacity == keys - 1
        np.testing.assert_array_equal(draw(r, CAM).rgba, full.rgba)
        assert r.device is None or r.device.capacity == keys
    finally:
        r.release()
    assert str(info.value) == _refusal(
        ctx, f"{keys:,} tile keys need", 8 * keys,
        "the tile renderer's keys buffer, 8 bytes a tile key", 8 * keys - 8)


def test_quad_device_order_cull_rows_and_prepass_are_checked(ctx, monkeypatch):
    """--sort gpu on the quad path: its cull rows (32 bytes a splat, uploaded once) and the
    pre-pass's prepared quads (64 bytes a slot) are refused in one line past the limit; at the
    limit it draws."""
    scene = _scene()
    settings = RenderSettings(sort_key=SortKey.GPU, early_stop="off")
    for limit, what, stride in ((32 * 1000 - 1, "the device order's cull rows", 32),
                                (64 * 1000 - 1, "the pre-pass's prepared quads", 64)):
        monkeypatch.setattr(limits, "MAX_BUFFER_BYTES", limit)
        r = QuadRenderer(ctx, scene, settings)
        try:
            with pytest.raises(SplatglError) as info:
                draw(r, CAM)
        finally:
            r.release()
        assert str(info.value) == _refusal(ctx, "1,000 splats need", stride * 1000,
                                           f"{what}, {stride} bytes a splat", limit)
    monkeypatch.setattr(limits, "MAX_BUFFER_BYTES", 64 * 1000)
    r = QuadRenderer(ctx, scene, settings)
    try:
        assert draw(r, CAM).rgba[..., 3].max() > 0.5
    finally:
        r.release()


def test_cli_refuses_the_tile_peak_buffer_in_one_line(monkeypatch, tmp_path, capsys):
    """``render --renderer tile --order per-pixel`` of the demo scene (1,604 splats) with room
    for one byte less than its 48-byte-a-splat peak buffer: one line, exit 2, nothing written."""
    out = tmp_path / "x.png"
    monkeypatch.setattr(limits, "MAX_BUFFER_BYTES", 1604 * 48 - 1)
    rc = main(["render", str(REPO / "scenes" / "demo.ply"), "--renderer", "tile", "--order",
               "per-pixel", "--width", "32", "--height", "24", "-o", str(out)])
    stdout, err = capsys.readouterr()
    assert (rc, stdout) == (2, "")
    assert err.startswith("splatgl: error: 1,604 splats need a GPU buffer of 76,992 bytes (the "
                          "tile renderer's peak buffer, 48 bytes a splat), more than this OpenGL "
                          "driver allows in one (76,991 bytes, ") and err.count("\n") == 1
    assert list(tmp_path.iterdir()) == []
