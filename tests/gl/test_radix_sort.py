"""The device radix sort: its NumPy twin and the compute shaders give exactly NumPy's stable
argsort (keys with values carried, every downsweep path the device has) and the CPU depth sort's
order (depth, ties by index), bit for bit; a quad frame sorted on the device is identical."""

from __future__ import annotations

import os
import shutil
import subprocess

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from helpers import draw, view_for
from splatgl.cameras.camera import Camera
from splatgl.cameras.poses import look_at
from splatgl.errors import ShaderError
from splatgl.gl import radix_block, radix_sort
from splatgl.gl.egl_devices import is_software_renderer
from splatgl.gl.shaders import ProgramCache, preprocess
from splatgl.gl.radix_sort import TILE_KEYS, RadixSorter, device_depth_sort, subgroup_paths
from splatgl.splatmath.radix import radix_passes, radix_sort_twin
from splatgl.renderers.quad import QuadRenderer
from splatgl.scene.splats import Scene
from splatgl.scene.settings import RenderSettings, SortKey
from splatgl.order.sort import depth_sort


def _depths(n: int, seed: int, ties: bool) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    z = np.exp(rng.uniform(-3, 6, n)).astype(np.float32)  # exponents differ: all 8 passes
    if ties:
        z[rng.integers(0, n, n // 3)] = z[0]
    idx = np.sort(rng.choice(4 * n, n, replace=False)).astype(np.uint32)
    return z, idx


@given(st.lists(st.floats(2.0 ** -10, 8192.0, width=32), min_size=0, max_size=300))
@settings(max_examples=60)
def test_twin_equals_cpu_sort(values):
    z = np.array(values, np.float32)
    idx = np.arange(z.size, dtype=np.uint32) * 3
    _, got = radix_sort_twin(z.view(np.uint32), idx)
    np.testing.assert_array_equal(got, depth_sort(z, idx))


@given(st.lists(st.integers(0, 2 ** 20), min_size=0, max_size=200), st.integers(0, 12))
@settings(max_examples=60)
def test_twin_is_a_stable_argsort_of_any_keys(values, shift):
    keys = (np.array(values, np.uint32) << np.uint32(shift)) | np.uint32(0x80000000)
    payload = np.arange(keys.size, dtype=np.uint32)[::-1].copy()
    got_keys, got_values = radix_sort_twin(keys, payload)
    want = np.argsort(keys, kind="stable")
    np.testing.assert_array_equal(got_keys, keys[want])
    np.testing.assert_array_equal(got_values, payload[want])


@given(st.lists(st.integers(0, 2 ** 32 - 1), min_size=0, max_size=200), st.sampled_from([8, 11]))
@settings(max_examples=60)
def test_twin_sorts_by_either_digit_width(values, bits):
    keys = np.array(values, np.uint32)
    payload = np.arange(keys.size, dtype=np.uint32)
    got_keys, got_values = radix_sort_twin(keys, payload, bits)
    np.testing.assert_array_equal(got_values, np.argsort(keys, kind="stable"))
    assert len(radix_passes(keys, bits)) <= -(-32 // bits)


def test_block_passes_cover_the_differing_bits_in_11_bit_digits():
    assert radix_passes(np.array([1 << 4, 1 << 27], np.uint32), 11) == [4, 15, 26]
    assert radix_passes(np.array([0, 0xFFFFFFFF], np.uint32), 11) == [0, 11, 22]
    assert radix_passes(np.array([0x100, 0x300], np.uint32), 11) == [9]


def test_software_devices_sort_with_the_block_passes(ctx, programs):
    """What the device is decides the design: the block passes on llvmpipe (the work-group
    design on GPUs, on request here)."""
    if not is_software_renderer(ctx.info["GL_RENDERER"]):
        pytest.skip("written for a software renderer")
    s = RadixSorter(ctx, programs)
    try:
        assert (s.path, s.digit_bits) == ("block", 11)
    finally:
        s.release()
    s = RadixSorter(ctx, programs, block=False)
    try:
        assert s.path in ("khr", "arb", "portable") and s.digit_bits == 8 and s.narrow
    finally:
        s.release()


def test_block_passes_that_fail_fall_back_to_the_work_group_design(ctx, programs, monkeypatch):
    """A software device whose compiler refuses the block passes (or whose order comes out
    wrong) still sorts, with the work-group design; asked for by name, the failure is raised."""
    if not is_software_renderer(ctx.info["GL_RENDERER"]):
        pytest.skip("written for a software renderer")

    def refuse(*args, **kwargs):
        raise ShaderError("radix_block_count.comp: refused")
    monkeypatch.setattr(radix_sort, "BlockPasses", refuse)
    s = RadixSorter(ctx, programs)
    try:
        assert s.path in ("khr", "arb", "portable") and s.digit_bits == 8 and s._block is None
        keys = np.arange(3000, dtype=np.uint32)[::-1] % np.uint32(11)
        np.testing.assert_array_equal(s.sort_values(keys, np.arange(3000, dtype=np.uint32)),
                                      np.argsort(keys, kind="stable"))
    finally:
        s.release()
    with pytest.raises(ShaderError, match="refused"):
        RadixSorter(ctx, programs, path="block")


def test_block_passes_run_two_work_groups_a_software_rasteriser_thread(monkeypatch):
    monkeypatch.setenv("LP_NUM_THREADS", "3")
    assert radix_block.block_groups() == 6
    monkeypatch.setenv("LP_NUM_THREADS", "0")  # llvmpipe without threads: the calling one
    assert radix_block.block_groups() == 2
    monkeypatch.setenv("LP_NUM_THREADS", "500")
    assert radix_block.block_groups() == radix_block.MAX_GROUPS
    monkeypatch.delenv("LP_NUM_THREADS")
    assert radix_block.block_groups() == max(2, 2 * (os.cpu_count() or 1))


def test_passes_cover_only_the_bits_keys_differ_in():
    keys = np.array([0x3F800000, 0x3F8000FF], np.uint32)  # differ in the low 8 bits only
    assert radix_passes(keys) == [0]
    assert radix_passes(np.array([0x100, 0x300, 0x500], np.uint32)) == [9]  # bits 9, 10
    assert radix_passes(np.array([1 << 4, 1 << 27], np.uint32)) == [4, 12, 20]
    assert radix_passes(np.array([5, 5], np.uint32)) == []
    assert radix_passes(np.array([7], np.uint32)) == []
    assert radix_passes(np.array([0, 0xFFFFFFFF], np.uint32)) == [0, 8, 16, 24]


def _keys(kind: str, n: int, rng) -> np.ndarray:
    """Test keys: full 32-bit, many duplicates, all equal, 1 or 3 passes from a shifted range."""
    if kind == "random":
        return rng.integers(0, 2 ** 32, n, dtype=np.uint64).astype(np.uint32)
    if kind == "duplicates":
        return (rng.integers(0, 40, n).astype(np.uint32) << np.uint32(13)) | np.uint32(0xF0000001)
    if kind == "equal":
        return np.full(n, 0xDEADBEEF, np.uint32)
    if kind == "one pass":
        return rng.integers(0, 200, n).astype(np.uint32) << np.uint32(20)
    if kind == "two block passes":  # 20 bits: 2 passes of 11 (the last writes A), 3 of 8
        return rng.integers(0, 1 << 20, n).astype(np.uint32) << np.uint32(5)
    return rng.integers(0, 1 << 24, n).astype(np.uint32) << np.uint32(3)  # three passes


KINDS = ("random", "duplicates", "equal", "one pass", "two block passes", "three passes")
SIZES = (0, 1, 2, 7, TILE_KEYS - 1, TILE_KEYS, TILE_KEYS + 1, 3 * TILE_KEYS + 123, 60_000)


@pytest.fixture(scope="module")
def programs(ctx):
    """One program cache for the module: each sorter compiles nothing another one did."""
    cache = ProgramCache(ctx)
    yield cache
    cache.release()


@pytest.fixture(scope="module", params=[
    "block", "block, keys and values apart", "subgroup", "portable",
    # the wide groups GPUs run: llvmpipe compiles them in 5-45 s
    pytest.param("subgroup, wide groups", marks=pytest.mark.slow),
    pytest.param("portable, wide groups", marks=pytest.mark.slow)])
def sorter(request, ctx, programs):
    """One sorter per design, downsweep path and group shape (reused across sizes, as a
    renderer reuses it): the block passes (software devices' default), and the work-group
    design, which on llvmpipe runs one warp per group; the wide-group ones are the shape GPUs
    run."""
    if request.param.startswith("block"):
        s = RadixSorter(ctx, programs, path="block")
        assert s._block.pairs_fit(s._capacity)  # llvmpipe has 64-bit integers
        if request.param.endswith("apart"):
            # as past 16.7M keys (a pair buffer over the 128 MB storage block limit) or on a
            # device without 64-bit integers: keys and values apart between passes
            s._block._block_limit = 0
            s.reserve(s._capacity + 1)
            assert len(s._bufs) == 7
        yield s
        s.release()
        return
    paths = subgroup_paths(ctx)
    path = "portable" if request.param.startswith("portable") else paths[0]
    if request.param.startswith("subgroup") and path == "portable":
        pytest.skip("no subgroup extension on this device")
    s = RadixSorter(ctx, programs, path=path, block=False,
                    narrow=False if request.param.endswith("wide groups") else None)
    yield s
    s.release()


@pytest.mark.parametrize("n", SIZES)
@pytest.mark.parametrize("kind", KINDS)
def test_device_sort_is_numpys_stable_argsort(sorter, n, kind):
    rng = np.random.default_rng(n + len(kind))
    keys = _keys(kind, n, rng)
    values = rng.integers(0, 2 ** 32, n, dtype=np.uint64).astype(np.uint32)  # a payload
    want = np.argsort(keys, kind="stable")
    got_keys, got_values = sorter.sort(keys, values)
    np.testing.assert_array_equal(got_keys, keys[want])
    np.testing.assert_array_equal(got_values, values[want])
    if n >= 2:  # the device planned the passes the twin plans, nothing read back to do it
        shifts = radix_passes(keys, sorter.digit_bits)
        assert sorter.last_plan() == ((shifts[0] if shifts else 0), len(shifts))


@pytest.mark.parametrize("n", [2, TILE_KEYS + 1, 20_000])
@pytest.mark.parametrize("kind", ["random", "equal", "one pass", "three passes"])
def test_resident_sort_finds_the_key_bits_on_the_device(sorter, n, kind):
    """Keys written straight into the sorter's buffers (as a device-resident producer would):
    the bits kernel finds which bits differ, the plan reads them, the result lands in A."""
    rng = np.random.default_rng(n)
    keys = _keys(kind, n, rng)
    values = np.arange(n, dtype=np.uint32)
    sorter.reserve(n)
    k_a, v_a = sorter.buffers()
    k_a.write(keys)
    v_a.write(values)
    assert sorter.sort_buffers(n) == (k_a, v_a)
    want = np.argsort(keys, kind="stable")
    np.testing.assert_array_equal(np.frombuffer(v_a.read(4 * n), np.uint32), want)
    np.testing.assert_array_equal(np.frombuffer(k_a.read(4 * n), np.uint32), keys[want])
    shifts = radix_passes(keys, sorter.digit_bits)
    assert sorter.last_plan() == ((shifts[0] if shifts else 0), len(shifts))


@pytest.mark.parametrize("m", [0, 1, 2, TILE_KEYS + 5, 3 * TILE_KEYS])
def test_device_count_sorts_that_many_keys_and_no_more(sorter, ctx, m):
    """The count a GPU stage wrote (here: into a buffer at byte offset 8) sizes the sort on the
    device: the first m keys sorted, those after untouched; a count above the buffers' capacity
    sorts what they hold (the tile renderer's overflow)."""
    n = 3 * TILE_KEYS
    rng = np.random.default_rng(m)
    keys = rng.integers(0, 5000, n).astype(np.uint32)
    sorter.reserve(n)
    k_a, v_a = sorter.buffers()
    k_a.write(keys)
    v_a.write(np.arange(n, dtype=np.uint32))
    count = ctx.buffer(np.array([7, 7, m, 7], np.uint32).tobytes())
    try:
        sorter.sort_buffers(n, device_count=(count, 8))
    finally:
        count.release()
    got = np.frombuffer(v_a.read(4 * n), np.uint32)
    want = np.argsort(keys[:m], kind="stable") if m >= 2 else np.arange(m)
    np.testing.assert_array_equal(got[:m], want)
    np.testing.assert_array_equal(got[m:], np.arange(m, n))
    np.testing.assert_array_equal(np.frombuffer(k_a.read(4 * n), np.uint32)[:m], keys[:m][want])


def test_device_count_above_the_capacity_sorts_the_capacity(sorter, ctx):
    sorter.reserve(TILE_KEYS + 3)
    n = sorter._capacity          # the buffers' size (the largest reserved so far)
    keys = (np.arange(n, dtype=np.uint32) * np.uint32(7919)) % np.uint32(1013)
    k_a, v_a = sorter.buffers()
    k_a.write(keys)
    v_a.write(np.arange(n, dtype=np.uint32))
    count = ctx.buffer(np.array([n + 1000], np.uint32).tobytes())
    try:
        sorter.sort_buffers(n, device_count=(count, 0))
    finally:
        count.release()
    np.testing.assert_array_equal(np.frombuffer(v_a.read(4 * n), np.uint32),
                                  np.argsort(keys, kind="stable"))


@pytest.mark.slow
def test_device_sort_of_a_million_keys(sorter):
    rng = np.random.default_rng(1)
    keys = np.exp(rng.uniform(-3, 6, 1_000_000)).astype(np.float32).view(np.uint32)
    keys[rng.integers(0, keys.size, keys.size // 3)] = keys[0]
    values = np.arange(keys.size, dtype=np.uint32)
    np.testing.assert_array_equal(sorter.sort_values(keys, values),
                                  np.argsort(keys, kind="stable"))


def test_subgroup_and_portable_paths_agree(ctx, programs):
    """Both ranking paths run here where llvmpipe exposes GL_ARB_shader_ballot."""
    paths = subgroup_paths(ctx)
    assert "portable" in paths
    rng = np.random.default_rng(5)
    keys = rng.integers(0, 300, 20_000).astype(np.uint32) * np.uint32(1 << 11)
    values = np.arange(keys.size, dtype=np.uint32)
    results = []
    for path in dict.fromkeys([paths[0], "portable"]):
        s = RadixSorter(ctx, programs, path=path)
        try:
            assert s.path == path
            # one warp per work group on a CPU renderer, wide groups on a GPU
            assert s.narrow == is_software_renderer(ctx.info["GL_RENDERER"])
            results.append(s.sort_values(keys, values))
        finally:
            s.release()
    for got in results:
        np.testing.assert_array_equal(got, np.argsort(keys, kind="stable"))


@pytest.mark.skipif(shutil.which("glslangValidator") is None, reason="glslangValidator not installed")
@pytest.mark.parametrize("narrow", [False, True])
def test_khr_subgroup_path_is_valid_glsl(tmp_path, narrow):
    """llvmpipe exposes no GL_KHR_shader_subgroup, so that path cannot run here: glslang at
    least checks that it compiles (and the probe; a driver that refuses either falls back)."""
    defines = {"RADIX_MATCH_KHR": 1, "RADIX_WARP": 8 if narrow else 32}
    if narrow:
        defines.update(RADIX_GROUP=8, RADIX_ITEMS=TILE_KEYS // 8, RADIX_NARROW=1)
    for name in ("radix_downsweep.comp", "radix_subgroup.comp"):
        path = tmp_path / name
        path.write_text(preprocess(name, defines).text)
        done = subprocess.run(["glslangValidator", str(path)], capture_output=True, text=True)
        assert done.returncode == 0, done.stdout + done.stderr


def test_a_path_that_sorts_wrongly_is_not_used(ctx, programs, monkeypatch):
    """A driver whose subgroups are not the size its probe said (Intel compiles at SIMD8, 16
    or 32 per shader): the sorter checks its order once and falls back to the next path."""
    if subgroup_paths(ctx) != ["arb", "portable"]:
        pytest.skip("written for llvmpipe's paths")
    monkeypatch.setattr(radix_sort, "_subgroup_size", lambda *args: 16)  # llvmpipe's is 8
    s = RadixSorter(ctx, programs, block=False)
    try:
        assert s.path == "portable"
        keys = np.arange(5000, dtype=np.uint32)[::-1] % np.uint32(7)
        np.testing.assert_array_equal(s.sort_values(keys, np.arange(5000, dtype=np.uint32)),
                                      np.argsort(keys, kind="stable"))
    finally:
        s.release()
    with pytest.raises(ShaderError, match="radix sort path arb .subgroup size 16. sorts wrongly"):
        RadixSorter(ctx, programs, path="arb")


def test_unknown_path_is_refused(ctx):
    with pytest.raises(ValueError, match="radix sort path 'cuda'"):
        RadixSorter(ctx, path="cuda")


@pytest.mark.parametrize("n", [1, 7, TILE_KEYS + 1, 60_000])
@pytest.mark.parametrize("ties", [False, True])
def test_device_depth_sort_equals_cpu_sort_bit_for_bit(ctx, programs, n, ties):
    z, idx = _depths(n, n, ties)
    sorter = RadixSorter(ctx, programs)
    try:
        np.testing.assert_array_equal(device_depth_sort(sorter, z, idx), depth_sort(z, idx))
    finally:
        sorter.release()


def test_quad_frame_with_device_sort_is_identical(ctx):
    rng = np.random.default_rng(3)
    n = 5000
    scene = Scene(rng.uniform(-1, 1, (n, 3)), rng.normal(size=(n, 4)), rng.normal(-3.5, 0.5, (n, 3)),
                  rng.normal(0, 2, n), rng.normal(0, 0.5, (n, 4, 3)))
    camera = Camera.from_fov(96, 64, 60.0, look_at(np.array([0.2, -0.3, -3.0]), np.zeros(3)))
    images, orders = [], []
    for key in (SortKey.EXACT, SortKey.GPU):
        r = QuadRenderer(ctx, scene, RenderSettings(sort_key=key))
        try:
            images.append(draw(r, camera).rgba)
            orders.append(r.order(view_for(r, camera)).copy())
        finally:
            r.release()
    np.testing.assert_array_equal(orders[1], orders[0])
    np.testing.assert_array_equal(images[1], images[0])
