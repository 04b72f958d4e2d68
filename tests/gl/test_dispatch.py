"""splatgl/gl/dispatch.py: the driver's work-group limit, and the radix sort's passes under a
lowered one (the per-splat passes' split frames: tests/renderers/test_dispatch_split.py)."""

from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np
import pytest

from splatgl.errors import SplatglError
from splatgl.gl import dispatch
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
