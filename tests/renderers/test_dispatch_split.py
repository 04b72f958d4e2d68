"""Compute dispatches past the driver's group count (splatgl/gl/dispatch.py): a dispatch of
more than GL_MAX_COMPUTE_WORK_GROUP_COUNT groups does nothing (a black frame, no error), so
every per-item pass splits.  With the limit lowered to a few groups, small scenes split their
passes: the frames are bit-identical to the unsplit ones; a pass that cannot split refuses in
one line."""

from __future__ import annotations

import dataclasses

import moderngl
import numpy as np
import pytest

from helpers import random_scene
from splatgl.api import default_camera
from splatgl.errors import SplatglError
from splatgl.gl import dispatch
from splatgl.scene.settings import EarlyStop, Preprocess, RenderSettings, RendererKind, SortKey

SCENE = random_scene(6000, seed=17, degree=1)
#: The same splats as another scene object (a renderer of its own: nothing kept from SCENE's).
TWIN = random_scene(6000, seed=17, degree=1)
CAMERA = default_camera(SCENE, 96, 72)
#: The lowered limit: the early-termination coverage pass always runs 16 groups (it never
#: splits: 16384 slots an invocation); the pre-pass, the device order's passes and the tile
#: renderer's per-splat passes run 24 to 47 here.
LIMIT = 16


@pytest.fixture
def lowered(monkeypatch):
    """lowered(n): the limit is n groups, and every direct dispatch is recorded (its sizes
    appended to lowered.sizes)."""
    original = moderngl.ComputeShader.run

    def recorded(prog, group_x=1, group_y=1, group_z=1):
        lower.sizes.append((group_x, group_y, group_z))
        return original(prog, group_x, group_y, group_z)

    def lower(limit):
        monkeypatch.setattr(dispatch, "LIMIT_OVERRIDE", limit)
        lower.sizes = []
    lower.sizes = []
    monkeypatch.setattr(moderngl.ComputeShader, "run", recorded)
    return lower


def _both(gl_renderer, lowered, settings, kind=RendererKind.QUAD):
    whole = gl_renderer.render(SCENE, CAMERA, settings, kind)
    assert whole[..., 3].max() > 0.5          # not a black frame
    assert max(max(size) for size in lowered.sizes) > LIMIT   # unlowered: larger dispatches
    lowered(LIMIT)
    split = gl_renderer.render(TWIN, CAMERA, settings, kind)
    assert lowered.sizes and max(max(size) for size in lowered.sizes) <= LIMIT
    lowered(None)
    return whole, split


@pytest.mark.parametrize("early_stop", [EarlyStop.OFF, EarlyStop.ON], ids=["plain", "stop"])
@pytest.mark.parametrize("key", [SortKey.EXACT, SortKey.GPU], ids=["cpu-sort", "gpu-sort"])
def test_quad_frames_split_bit_identical(gl_renderer, lowered, key, early_stop):
    settings = RenderSettings(sort_key=key, early_stop=early_stop)
    whole, split = _both(gl_renderer, lowered, settings)
    np.testing.assert_array_equal(split, whole)


def test_quad_prepass_split_equals_vertex_path(gl_renderer, lowered):
    settings = RenderSettings(early_stop=EarlyStop.OFF)
    lowered(2)
    split = gl_renderer.render(TWIN, CAMERA, settings)
    lowered(None)
    vertex = gl_renderer.render(SCENE, CAMERA,
                                dataclasses.replace(settings, preprocess=Preprocess.VERTEX))
    np.testing.assert_allclose(split, vertex, atol=2e-5)


@pytest.mark.parametrize("key", [SortKey.EXACT, SortKey.GPU], ids=["cpu-order", "device-order"])
def test_tile_frame_split_bit_identical(gl_renderer, lowered, key):
    whole, split = _both(gl_renderer, lowered, RenderSettings(sort_key=key), RendererKind.TILE)
    np.testing.assert_array_equal(split, whole)


def test_grid_covers_the_groups_within_the_limit():
    for groups in (1, 2, 3, 65535, 65536, 66000, 8 * 65535 + 1):
        x, y = dispatch.grid(groups, 65535)
        assert x <= 65535 and y <= 65535 and x * y >= groups and x * y - groups < y


def test_unsplit_pass_refuses_in_one_line(ctx, lowered):
    prog = ctx.compute_shader("#version 430\nlayout(local_size_x = 1) in;\nvoid main() {}\n")
    lowered(4)
    with pytest.raises(SplatglError, match=r"^9000 splats need 5 work groups, over this "
                                           r"driver's 4 in one compute dispatch; [^\n]*$"):
        dispatch.run(prog, 5, "9000 splats")
    with pytest.raises(SplatglError, match="need 7 work groups"):
        dispatch.run_indirect(prog, ctx.buffer(reserve=16), 0, 7, "9000 splats")
    dispatch.run(prog, 4, "9000 splats")    # within the limit: runs
