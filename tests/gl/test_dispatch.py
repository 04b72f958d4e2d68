"""splatgl/gl/dispatch.py: the driver's work-group limit, and the radix sort's passes under a
lowered one (the per-splat passes' split frames: tests/renderers/test_dispatch_split.py)."""

from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np
import pytest

from splatgl.errors import SplatglError
from splatgl.gl import dispatch, radix_block
from splatgl.gl.radix_sort import TILE_KEYS, RadixSorter
from splatgl.gl.shaders import preprocess


def test_limit_is_the_contexts_group_count(ctx, monkeypatch):
    monkeypatch.setattr(dispatch, "LIMIT_OVERRIDE", None)
    counts = ctx.info["GL_MAX_COMPUTE_WORK_GROUP_COUNT"]
    assert dispatch.group_limit(ctx) == min(counts[0], counts[1], 65535)
    monkeypatch.setattr(dispatch, "LIMIT_OVERRIDE", 3)
    assert dispatch.group_limit(ctx) == dispatch.portable_limit() == 3


def test_split_dispatch_covers_every_group_once(ctx, monkeypatch):
    """A dispatch of 11 groups under a limit of 4 runs as 4 + 4 + 3 with u_group_offset:
    linear_invocation() reaches every item once."""
    src = ("#version 430\nlayout(local_size_x = 8) in;\n#include \"lib/dispatch.glsl\"\n"
           "layout(std430, binding = 0) buffer Out { uint hits[]; };\n"
           "void main() { atomicAdd(hits[linear_invocation()], 1u); }\n")
    shader = dispatch_shader(ctx, src)
    out = ctx.buffer(reserve=4 * 88)
    out.clear()
    out.bind_to_storage_buffer(0)
    monkeypatch.setattr(dispatch, "LIMIT_OVERRIDE", 4)
    dispatch.run(shader, 11, "88 items")
    ctx.memory_barrier()
    np.testing.assert_array_equal(np.frombuffer(out.read(), np.uint32), np.ones(88, np.uint32))
    assert shader["u_group_offset"].value == 0     # left as indirect dispatches read it
    out.release()


def dispatch_shader(ctx, text: str):
    """A compute shader from ``text`` with the repository's includes."""
    with tempfile.TemporaryDirectory() as tmp:
        (Path(tmp) / "probe.comp").write_text(text)
        (Path(tmp) / "lib").symlink_to(Path(__file__).resolve().parents[2] / "shaders" / "lib")
        return ctx.compute_shader(preprocess("probe.comp", root=Path(tmp)).text)


def test_radix_sort_past_the_limit_refuses_in_one_line(ctx, monkeypatch):
    """The work-group design's passes (GPUs) do not split: past the limit they refuse before
    dispatching rather than leave the keys unsorted; the block passes (software devices) run
    a fixed few groups, and sort as NumPy's stable argsort whatever the limit."""
    rng = np.random.default_rng(3)
    keys = rng.integers(0, 1 << 20, 5 * TILE_KEYS, dtype=np.uint32)
    values = np.arange(keys.size, dtype=np.uint32)
    monkeypatch.setattr(dispatch, "LIMIT_OVERRIDE", 4)
    s = RadixSorter(ctx, block=False)
    try:
        with pytest.raises(SplatglError, match=r"^\d+ sort keys need 5 work groups, over this "
                                               r"driver's 4 in one compute dispatch; [^\n]*$"):
            s.sort_values(keys, values)
    finally:
        s.release()
    s = RadixSorter(ctx, block=True)
    try:
        np.testing.assert_array_equal(s.sort_values(keys, values),
                                      np.argsort(keys, kind="stable"))
    finally:
        s.release()


def test_block_sort_runs_more_groups_for_more_keys(ctx, monkeypatch):
    """llvmpipe ends an invocation's loops after 65535 iterations in all: a lane of the block
    passes owns at most LANE_KEYS keys, so more keys run more groups (lowered here so a small
    sort needs them), and the order stays NumPy's stable argsort."""
    monkeypatch.setattr(radix_block, "LANE_KEYS", 1024)
    rng = np.random.default_rng(4)
    keys = rng.integers(0, 1 << 24, 100_000, dtype=np.uint32) << np.uint32(4)
    s = RadixSorter(ctx, block=True)
    try:
        first = s._block.groups
        got = s.sort_values(keys, np.arange(keys.size, dtype=np.uint32))
        assert s._block.groups == max(first, -(-keys.size // (8 * 1024))) == 13
        np.testing.assert_array_equal(got, np.argsort(keys, kind="stable"))
        with pytest.raises(SplatglError, match=r"^600000 sort keys are more than [^\n]*--sort exact"):
            s.reserve(600_000)
    finally:
        s.release()


@pytest.mark.slow
def test_block_sort_of_8_3_million_keys(ctx):
    """The size that came out unsorted (each of 32 lanes past llvmpipe's loop limit)."""
    rng = np.random.default_rng(5)
    keys = rng.integers(0, 1 << 31, 8_300_000, dtype=np.uint32)
    s = RadixSorter(ctx, block=True)
    try:
        np.testing.assert_array_equal(s.sort_values(keys, np.arange(keys.size, dtype=np.uint32)),
                                      np.argsort(keys, kind="stable"))
    finally:
        s.release()
