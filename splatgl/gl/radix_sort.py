"""Device sort: a compute-shader LSD radix sort of 32-bit keys with a 32-bit payload.

Two designs, by device: on software rasterisers (llvmpipe) the block passes of
:mod:`splatgl.gl.radix_block` (each invocation sorts a contiguous block serially: the CPU
parallel radix sort, with no barriers or shared memory); on GPUs the work-group design below.
Both are stable and give the same order.

The work-group design (reduce-then-scan, as in GPUSorting's DeviceRadixSort; ranking by
warp-level multi-split, as in Onesweep), in dispatches that read their sizes from the device:

1. ``radix_bits.comp``: the OR and the AND of all keys.
2. ``radix_plan.comp``: the bits in which keys differ give the passes: RADIX_BITS-bit digits
   from the lowest differing bit up to the highest, so bits every key shares cost nothing.  It
   writes each pass slot's dispatch size (0 for a pass the keys do not need) and digit shift
   into the state buffer, which the passes' ``glDispatchComputeIndirect`` read: nothing is read
   back to plan a sort.
   The key count lives in the state too: the host writes it, or :meth:`RadixSorter.sort_buffers`
   copies it from a buffer a GPU stage wrote (``device_count``), so a sort of a device-sized
   set of keys (the tile renderer's (tile, depth) keys) reads no count back.
3. Per pass slot (``32 / RADIX_BITS`` of them): ``radix_upsweep.comp`` counts each tile's digits
   in shared memory; ``radix_scan.comp`` (one work group per digit, work-efficient) turns the
   counts into each tile's start for each digit; ``radix_downsweep.comp`` ranks the tile's keys
   stably and writes keys and values at their places.  Passes alternate A -> B -> A.
4. ``radix_copy.comp``: after an odd number of passes, B back into A; a sort always leaves its
   result in the A buffers (a draw can bind them without knowing how many passes ran).

The downsweep ranks with subgroup operations where the device has them (``GL_KHR_shader_subgroup``
ballots, or ``GL_ARB_shader_ballot`` broadcasts, which llvmpipe exposes) and through shared
memory where it does not (the ``portable`` path); all give the same order.  Every pass is
stable, so the whole sort is: equal keys keep their input order.  Fed the cull's ascending
indices with the float32 bits of their depths, it gives exactly
:func:`splatgl.order.sort.depth_sort`'s order (ties by index), which the tests check bit for
bit.

:func:`splatgl.splatmath.radix.radix_sort_twin` is the NumPy twin: the same digits, passes and skip rule.
"""

from __future__ import annotations

import moderngl
import numpy as np

from ..constants import RADIX_BITS, RADIX_BLOCK_BITS, RADIX_ITEMS
from ..errors import ShaderError
from ..splatmath.radix import key_bits
from .bindings import (RADIX_BINDING_HIST, RADIX_BINDING_KEYS_IN, RADIX_BINDING_KEYS_OUT,
                       RADIX_BINDING_STATE, RADIX_BINDING_VALS_IN, RADIX_BINDING_VALS_OUT,
                       RADIX_BLOCK_LANES, RADIX_GROUP, RADIX_PORTABLE_WARP)
from . import dispatch
from .egl_devices import is_software_renderer
from .radix_block import BLOCK_SLOTS, BlockPasses, groups_for, pair_bytes
from .shaders import ProgramCache
from .transfers import transfers

#: Keys one work group owns per pass.
TILE_KEYS = RADIX_GROUP * RADIX_ITEMS
RADIX = 1 << RADIX_BITS
#: Pass slots: enough RADIX_BITS-bit digits for 32-bit keys.
SLOTS = 32 // RADIX_BITS
#: The downsweep's ways of ranking (see the module doc), best first; ``block``: the block
#: passes instead of the work-group design (software devices' default).
PATHS = ("khr", "arb", "portable")
BLOCK = "block"

# The state buffer (lib/radix.glsl, RadixState, std430): 4 uints, the key count and 3 spare,
# then uvec4 per pass slot (dispatch size, shift), uvec4 per slot (the scan's dispatch size),
# one uvec4 (the copy's), uvec4 per slot twice (the block passes' scatters), then the digit
# totals.  Byte offsets of the count and of the indirect dispatch arguments:
_COUNT = 16
_PASS_ARGS = 32
_SCAN_ARGS = _PASS_ARGS + 16 * SLOTS
_COPY_ARGS = _SCAN_ARGS + 16 * SLOTS
_MID_ARGS = _COPY_ARGS + 16
_LAST_ARGS = _MID_ARGS + 16 * SLOTS
_STATE_BYTES = _LAST_ARGS + 16 * SLOTS + 4 * SLOTS * RADIX
_BLOCK_ARGS = {"pass": _PASS_ARGS, "scan": _SCAN_ARGS, "mid": _MID_ARGS, "last": _LAST_ARGS,
               "copy": _COPY_ARGS}
assert BLOCK_SLOTS <= SLOTS


def subgroup_paths(ctx: moderngl.Context) -> list[str]:
    """The downsweep paths this context can compile, best first (``portable`` always)."""
    ext = ctx.extensions
    return ([p for p, name in (("khr", "GL_KHR_shader_subgroup"), ("arb", "GL_ARB_shader_ballot"))
             if name in ext] + ["portable"])


def _subgroup_size(programs: ProgramCache, state: moderngl.Buffer, path: str) -> int:
    """The device's subgroup size, read back once from a one-invocation probe into ``state``."""
    prog = programs.compute("radix_subgroup.comp", {f"RADIX_MATCH_{path.upper()}": 1})
    state.bind_to_storage_buffer(RADIX_BINDING_STATE)
    prog.run(group_x=1)
    return int(np.frombuffer(state.read(4), np.uint32)[0])


class RadixSorter:
    """Sorts (M,) uint32 keys with uint32 values on the device; reuse it, then :meth:`release`.

    ``path`` ``"block"`` runs the block passes (:mod:`splatgl.gl.radix_block`), by default on
    software renderers; otherwise it picks the work-group design's ranking (:data:`PATHS`), by
    default the best the context offers whose shaders compile with a subgroup size that
    divides RADIX_GROUP.  ``block=False`` asks for the work-group design on a software
    renderer.  ``narrow`` runs one warp per work group with TILE_KEYS / warp keys a lane
    (radix_downsweep.comp: no per-warp histograms to clear and scan), by default on software
    renderers, where a work group runs on one CPU thread and a warp is its SIMD lanes
    (llvmpipe's 8).  Software renderers are those
    :func:`splatgl.gl.egl_devices.is_software_renderer` names, as for the device class
    (:mod:`splatgl.gl.device_class`); where the block passes do not compile or sort rightly
    there, the sorter falls back to the work-group design.  Buffers grow to the largest M seen
    and are kept between calls.
    """

    def __init__(self, ctx: moderngl.Context, programs: ProgramCache | None = None,
                 path: str | None = None, narrow: bool | None = None, block: bool | None = None):
        self.ctx = ctx
        self.programs = programs or ProgramCache(ctx)
        if path is not None and path not in PATHS + (BLOCK,):
            raise ValueError(f"radix sort path {path!r}: expected one of "
                             f"{', '.join(PATHS + (BLOCK,))}")
        # what the device is decides the design, as in gl/device_class.py's classify (whose
        # measured probe sorts with this class, so it cannot ask it); SPLATGL_DEVICE_CLASS,
        # which forces the --sort/--early-stop defaults, leaves llvmpipe's sort as it is
        self._software = is_software_renderer(ctx.info.get("GL_RENDERER", ""))
        self._capacity = 0
        # keys A, values A, keys B, values B, hist; the block passes: keys A, values A, hist,
        # then B and C (a pair buffer each, or keys and values each)
        self._bufs: list[moderngl.Buffer] = []
        self._state = ctx.buffer(reserve=_STATE_BYTES)
        self._narrow = narrow
        by_default = path is None and (block if block is not None else self._software)
        path = BLOCK if by_default else path
        self._block: BlockPasses | None = None
        #: Bits of a pass's digits (the twin's ``bits``).
        self.digit_bits = RADIX_BLOCK_BITS if path == BLOCK else RADIX_BITS
        try:
            try:
                self.path, self.warp, self.narrow, self._progs = self._choose(path)
            except ShaderError:
                if not by_default:
                    raise
                self._drop_buffers()  # the block passes' layout
                self._block, self.digit_bits = None, RADIX_BITS
                self.path, self.warp, self.narrow, self._progs = self._choose(None)
        except BaseException:
            self.release()
            raise

    def _choose(self, wanted: str | None):
        """(path, warp width, narrow, programs by name): ``wanted``, or the best path that
        compiles and sorts a test array right (a driver whose subgroups are not what its probe
        said, e.g. a varying SIMD width, falls back to the next)."""
        for path in [wanted] if wanted else subgroup_paths(self.ctx):
            try:
                return self._try(path)
            except ShaderError:
                if wanted:
                    raise
        raise ShaderError("radix sort: no downsweep path compiles")  # portable always should

    def _try(self, path: str):
        if path == BLOCK:
            self._block = BlockPasses(self.programs)
            self._progs = {}
            self._check(path, RADIX_BLOCK_LANES)
            return path, RADIX_BLOCK_LANES, False, self._progs
        warp, defines = RADIX_PORTABLE_WARP, {}
        if path != "portable":
            warp = _subgroup_size(self.programs, self._state, path)
            if warp < 1 or RADIX_GROUP % warp or TILE_KEYS % warp:
                raise ShaderError(f"radix sort path {path}: subgroup size {warp} does not "
                                  f"divide the work group ({RADIX_GROUP})")
            defines = {"RADIX_WARP": warp, f"RADIX_MATCH_{path.upper()}": 1}
        narrow = self._narrow if self._narrow is not None else self._software
        if narrow:  # one warp per group, many keys per lane
            defines.update(RADIX_GROUP=warp, RADIX_ITEMS=TILE_KEYS // warp, RADIX_NARROW=1)
        self._progs = {name: self.programs.compute(f"radix_{name}.comp", defines)
                       for name in ("bits", "plan", "upsweep", "scan", "downsweep", "copy")}
        self._check(path, warp)
        return path, warp, narrow, self._progs

    def _check(self, path: str, warp: int) -> None:
        """Sort a test array once: a ShaderError where the order is wrong on this device."""
        self._state.write(np.array([0, 0xFFFFFFFF], np.uint32).tobytes())  # no bits seen
        keys = (np.arange(2 * TILE_KEYS + 77, dtype=np.uint32) * np.uint32(2654435761)
                % np.uint32(3001)) << np.uint32(3)  # ties, two passes, a partial tile
        if not np.array_equal(self.sort_values(keys, np.arange(keys.size, dtype=np.uint32)),
                              np.argsort(keys, kind="stable")):
            raise ShaderError(f"radix sort path {path} (subgroup size {warp}) sorts wrongly "
                              "on this device")

    def reserve(self, count: int) -> None:
        """Room for ``count`` keys (the buffers are replaced, their contents lost, when they
        grow): call it before writing keys into :meth:`buffers` for :meth:`sort_buffers`."""
        if count <= self._capacity:
            return
        self._drop_buffers()
        if self._block is not None:   # each lane's block within llvmpipe's loop limit
            groups = groups_for(count, self._block.groups)
            if groups != self._block.groups:
                self._block = BlockPasses(self.programs, groups, self._block.bits)
        tiles = -(-count // TILE_KEYS)
        size = 16 * -(-count // 4)  # whole uvec4s (the block passes read 4 keys at a time)
        if self._block is None:
            self._bufs = [self.ctx.buffer(reserve=size) for _ in range(4)]
            self._bufs.append(self.ctx.buffer(reserve=4 * RADIX * tiles))
        elif self._block.pairs_fit(count):
            self._bufs = [self.ctx.buffer(reserve=size) for _ in range(2)]
            self._bufs.append(self.ctx.buffer(reserve=self._block.hist_bytes()))
            self._bufs += [self.ctx.buffer(reserve=pair_bytes(count)) for _ in range(2)]
        else:
            self._bufs = [self.ctx.buffer(reserve=size) for _ in range(2)]
            self._bufs.append(self.ctx.buffer(reserve=self._block.hist_bytes()))
            self._bufs += [self.ctx.buffer(reserve=size) for _ in range(4)]
        self._capacity = count

    def sort(self, keys: np.ndarray, values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(keys, values)`` (M,) uint32, sorted by key, equal keys in input order."""
        keys, values, count = self._upload(keys, values)
        if count < 2:
            return keys.copy(), values.copy()
        k_a, v_a = self.sort_buffers(count, key_bits(keys))
        return (np.frombuffer(k_a.read(4 * count), np.uint32),
                np.frombuffer(v_a.read(4 * count), np.uint32))

    def sort_values(self, keys: np.ndarray, values: np.ndarray) -> np.ndarray:
        """:meth:`sort`'s values alone (reads back half as much)."""
        keys, values, count = self._upload(keys, values)
        if count < 2:
            return values.copy()
        return np.frombuffer(self.sort_buffers(count, key_bits(keys))[1].read(4 * count), np.uint32)

    def _upload(self, keys: np.ndarray, values: np.ndarray):
        keys = np.ascontiguousarray(keys, np.uint32)
        values = np.ascontiguousarray(values, np.uint32)
        if keys.shape != values.shape or keys.ndim != 1:
            raise ValueError(f"radix sort: keys {keys.shape} and values {values.shape} must be "
                             "(M,) alike")
        if keys.size >= 2:
            self.reserve(keys.size)
            self._bufs[0].write(keys)
            self._bufs[1].write(values)
        return keys, values, keys.size

    def sort_buffers(self, count: int, bits: np.ndarray | None = None,
                     device_count: tuple[moderngl.Buffer, int] | None = None
                     ) -> tuple[moderngl.Buffer, moderngl.Buffer]:
        """Sort the first ``count`` keys and values of the A buffers (:meth:`buffers`, after
        :meth:`reserve`) in place on the device; returns them.  Nothing is read back.

        ``bits``: the keys' OR and AND (2,) uint32 where the caller has them (keys uploaded
        from NumPy), which saves the device reading every key once more to find them.
        ``device_count``: (buffer, byte offset) of a uint32 on the device holding how many keys
        to sort, which a GPU stage wrote (copied into the state on the device, never read
        back); ``count`` is then the most there can be (the buffers' size), and a device count
        above it sorts ``count`` keys."""
        self.reserve(count)
        k_a, v_a = self._bufs[:2]
        tiles = max(1, -(-self._capacity // TILE_KEYS))  # hist's rows; the plan sizes the passes
        progs = self._progs
        for prog in progs.values():
            for name, value in (("u_tiles", tiles), ("u_capacity", self._capacity)):
                if name in prog:
                    prog[name].value = value
        moved = transfers(self.ctx)
        if device_count is None:
            self._state.write(np.array([count], np.uint32), offset=_COUNT)
            moved.upload(4)
        else:
            self.ctx.copy_buffer(self._state, device_count[0], 4, read_offset=device_count[1],
                                 write_offset=_COUNT)
        self._state.bind_to_storage_buffer(RADIX_BINDING_STATE)
        if bits is not None:
            self._state.write(np.asarray(bits, np.uint32))
            moved.upload(8)
        if self._block is not None:
            rest = self._bufs[3:]
            half = len(rest) // 2
            sets = ((k_a, v_a), tuple(rest[:half]), tuple(rest[half:]))
            self._block.record(self.ctx, self._state, sets, self._bufs[2], self._capacity,
                               bits is None, _BLOCK_ARGS)
            for prog in self._block.programs.values():
                moved.uniforms(prog)
            return k_a, v_a
        k_b, v_b, hist = self._bufs[2:5]
        hist.bind_to_storage_buffer(RADIX_BINDING_HIST)
        if bits is None:
            k_a.bind_to_storage_buffer(RADIX_BINDING_KEYS_IN)
            dispatch.run(progs["bits"], tiles if device_count else max(1, -(-count // TILE_KEYS)),
                         f"{count} sort keys")
            self.ctx.memory_barrier()
        progs["plan"].run(group_x=1)
        self.ctx.memory_barrier()
        src, dst = (k_a, v_a), (k_b, v_b)
        for slot in range(SLOTS):
            self._bind(src, dst)
            for name in ("upsweep", "scan", "downsweep"):
                progs[name]["u_slot"].value = slot
            what = f"{self._capacity} sort keys"   # the plan sizes a pass to the tiles at most
            dispatch.run_indirect(progs["upsweep"], self._state, _PASS_ARGS + 16 * slot, tiles, what)
            self.ctx.memory_barrier()
            progs["scan"].run_indirect(self._state, _SCAN_ARGS + 16 * slot)   # RADIX groups
            self.ctx.memory_barrier()
            dispatch.run_indirect(progs["downsweep"], self._state, _PASS_ARGS + 16 * slot, tiles,
                                  what)
            for name in ("upsweep", "scan", "downsweep"):   # the uniforms of this pass slot
                moved.uniforms(progs[name])
            self.ctx.memory_barrier()
            src, dst = dst, src
        self._bind((k_b, v_b), (k_a, v_a))
        dispatch.run_indirect(progs["copy"], self._state, _COPY_ARGS, tiles,
                              f"{self._capacity} sort keys")
        self.ctx.memory_barrier()
        return k_a, v_a

    def _bind(self, src, dst) -> None:
        src[0].bind_to_storage_buffer(RADIX_BINDING_KEYS_IN)
        src[1].bind_to_storage_buffer(RADIX_BINDING_VALS_IN)
        dst[0].bind_to_storage_buffer(RADIX_BINDING_KEYS_OUT)
        dst[1].bind_to_storage_buffer(RADIX_BINDING_VALS_OUT)

    def buffers(self) -> tuple[moderngl.Buffer, moderngl.Buffer]:
        """The A keys and values buffers (:meth:`sort_buffers` sorts them)."""
        return self._bufs[0], self._bufs[1]

    def last_plan(self) -> tuple[int, int]:
        """(lowest differing bit, passes) of the last sort, read back (for tests)."""
        lo, passes = np.frombuffer(self._state.read(8, offset=8), np.uint32)
        return int(lo), int(passes)

    def _drop_buffers(self) -> None:
        for buf in self._bufs:
            buf.release()
        self._bufs = []
        self._capacity = 0

    def release(self) -> None:
        self._drop_buffers()
        self._state.release()


def device_depth_sort(sorter: RadixSorter, depth: np.ndarray, indices: np.ndarray) -> np.ndarray:
    """:func:`splatgl.order.sort.depth_sort` on the device: indices (M,) uint32 front to back by
    ``depth`` (M,) (positive, so its float32 bits order like the values), ties in input order
    (the cull's ascending indices: ties by index, as the CPU sort)."""
    if depth.size and not (depth > 0).all():
        raise ValueError("device_depth_sort needs positive depths (cull at the near plane first)")
    keys = np.ascontiguousarray(depth, np.float32).view(np.uint32)
    return sorter.sort_values(keys, indices)
