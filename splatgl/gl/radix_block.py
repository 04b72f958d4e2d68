"""The radix sort's block passes: the device sort on software devices (issue 40, item 2).

llvmpipe runs a work group as a loop on one CPU thread over 8-lane SIMD vectors, spreads the
groups over the CPU's cores, makes a barrier a coroutine switch and every storage or shared
access with per-lane addresses a loop over the lanes.  The work-group design
(:mod:`splatgl.gl.radix_sort`: shared-memory histograms, ballots, barriers) pays all of that;
this is the classic CPU parallel LSD radix sort instead, shaped for such a device:

- ``RADIX_BLOCK_GROUPS`` groups of ``RADIX_BLOCK_LANES`` invocations (*lanes*), two groups a
  CPU thread; each lane owns a contiguous block of the keys and works through it alone, reading
  4 keys a storage access (``uvec4``);
- ``radix_block_count.comp``: each lane counts its block's digits (RADIX_BLOCK_BITS = 11 bits:
  32-bit keys in at most 3 passes) in a private array, then writes them as its row of hist;
- ``radix_block_scan.comp`` (one work group): the exclusive scan of the counts in digit-major
  order, (digit, lane), in place, plus the digit starts;
- ``radix_block_scatter.comp``: each lane walks its block in order and writes each key and
  value at its digit's next place: stable by construction, with no barrier, no shared memory
  and no subgroup operation.  Between passes a key and its value travel as one ``uvec2``
  (one storage write instead of two) where the pair buffer fits the device's storage block
  limit (llvmpipe: 128 MB, 16.7M keys); apart otherwise.  On llvmpipe a ``uvec2`` write costs
  about 0.8 of a uint64 one (it stores the pair as two 32-bit components in one lane loop;
  the uint64 is packed and unpacked) and 0.7 of two 32-bit writes to separate buffers.

The passes run over only the bits in which keys differ, planned on the device
(``radix_plan.comp`` with ``RADIX_BLOCK``; ``radix_block_bits.comp`` finds the bits), with
indirect dispatches: nothing is read back.  Pass s reads A (s = 0) or what pass s - 1 wrote and
writes B (s even) or C (s odd), except that the last of several passes writes A; after a single
pass ``radix_block_copy.comp`` brings B into A.  The host records every slot's dispatches with
the buffers that slot would use and the plan gives the slots the keys do not need no work
groups.

Measured on llvmpipe (2 cores, AVX-512 Xeon): the scattered storage writes are most of the
time (each is a loop over the SIMD lanes in llvmpipe, and the 2048 digit streams miss the
caches); the digit counts in a private array cost a tenth of it; 8-bit digits (4 passes) cost
about what 11-bit ones (3 passes) do; ``benchmarks/radix_sort.py`` compares the designs.
"""

from __future__ import annotations

import os

import moderngl

from ..constants import RADIX_BLOCK_BITS
from ..errors import SplatglError
from .bindings import (RADIX_BINDING_HIST, RADIX_BINDING_KEYS_IN, RADIX_BINDING_KEYS_OUT,
                       RADIX_BINDING_VALS_IN, RADIX_BINDING_VALS_OUT, RADIX_BLOCK_LANES)
from .shaders import ProgramCache

#: Digit values of a block pass.
BLOCK_RADIX = 1 << RADIX_BLOCK_BITS
#: Block passes 32-bit keys can need.
BLOCK_SLOTS = -(-32 // RADIX_BLOCK_BITS)
#: Most work groups (a lane's digit counts cost a row of BLOCK_RADIX words in hist).
MAX_GROUPS = 64
#: llvmpipe's thread count setting (its default: one thread a CPU core).
THREADS_ENV = "LP_NUM_THREADS"
#: Most keys a lane owns: llvmpipe ends all of an invocation's loops after 65535 iterations in
#: total, and a lane reads its block 4 keys an iteration besides looping over the digits, so
#: past about 250k keys a lane (8.06M keys with 4 groups) the passes stopped short and left
#: the keys unsorted; a sort of more keys runs more groups (:func:`groups_for`).
LANE_KEYS = 4 * 32768


def block_groups() -> int:
    """Work groups of a block pass: two a CPU thread of the software rasteriser (``LP_NUM_THREADS``
    or the cores), so the threads share the work however the OS schedules them."""
    try:
        threads = int(os.environ.get(THREADS_ENV, ""))
    except ValueError:
        threads = os.cpu_count() or 1
    return max(2, min(MAX_GROUPS, 2 * max(1, threads)))


def groups_for(count: int, groups: int) -> int:
    """Work groups (at least ``groups``) whose lanes own at most :data:`LANE_KEYS` keys each
    of ``count``; a one-line refusal past :data:`MAX_GROUPS`."""
    needed = max(groups, -(-count // (RADIX_BLOCK_LANES * LANE_KEYS)))
    if needed > MAX_GROUPS:
        most = MAX_GROUPS * RADIX_BLOCK_LANES * LANE_KEYS
        raise SplatglError(f"{count} sort keys are more than the device radix sort's block "
                           f"passes sort on this software device ({most}); sort on the CPU "
                           "(--sort exact) or draw fewer splats")
    return needed


class BlockPasses:
    """The programs of the block passes for ``groups`` work groups, and the recording of a
    sort (:meth:`record`) into the buffers a :class:`~splatgl.gl.radix_sort.RadixSorter`
    holds.  Between passes keys and values travel as ``uvec2`` pairs (one storage write a key
    instead of two) where the pair buffers fit the device's storage block size
    (:meth:`pairs_fit`); apart otherwise."""

    def __init__(self, programs: ProgramCache, groups: int | None = None,
                 bits: int = RADIX_BLOCK_BITS):
        self.groups = groups or block_groups()
        self.lanes = self.groups * RADIX_BLOCK_LANES
        self.bits = bits
        self.slots = -(-32 // bits)
        self._cache = programs
        self._defines = {"RADIX_BLOCK": 1, "RADIX_BLOCK_GROUPS": self.groups,
                         "RADIX_BLOCK_BITS": bits}
        self.programs: dict[str, moderngl.ComputeShader] = {}  # by name and pairs in/out
        for name in ("bits", "plan", "scan"):
            self._program(name)
        ctx = programs.ctx
        self._block_limit = int(ctx.info.get("GL_MAX_SHADER_STORAGE_BLOCK_SIZE") or 0)

    def _program(self, name: str, src_pairs: bool = False, dst_pairs: bool = False):
        key = f"{name}{' pairs in' if src_pairs else ''}{' pairs out' if dst_pairs else ''}"
        if key not in self.programs:
            defines = dict(self._defines)
            if src_pairs:
                defines["RADIX_BLOCK_SRC_PAIRS"] = 1
            if dst_pairs:
                defines["RADIX_BLOCK_DST_PAIRS"] = 1
            file = "radix_plan.comp" if name == "plan" else f"radix_block_{name}.comp"
            self.programs[key] = self._cache.compute(file, defines)
        return self.programs[key]

    def pairs_fit(self, capacity: int) -> bool:
        """Whether a pair buffer of ``capacity`` keys fits one storage block here."""
        return pair_bytes(capacity) <= self._block_limit

    def hist_bytes(self) -> int:
        """Bytes of hist: a row of digit counts a lane, then the digit starts."""
        return 4 * (self.lanes + 1) * (1 << self.bits)

    def record(self, ctx: moderngl.Context, state: moderngl.Buffer, sets, hist, capacity: int,
               find_bits: bool, args: dict[str, int]) -> None:
        """Dispatch a sort of the A keys (the count is in ``state``): ``sets`` the buffers A
        (keys, values), B and C (one pair buffer each, or keys and values) of ``capacity``
        keys; ``find_bits``: run the bits kernel first (the state holds no OR/AND yet);
        ``args``: byte offsets in ``state`` of the indirect arguments by name (pass, scan, mid,
        last: per slot, 16 bytes each; copy)."""
        a, b, c = sets
        pairs = len(b) == 1
        progs = self.programs
        hist.bind_to_storage_buffer(RADIX_BINDING_HIST)
        if find_bits:
            self._set(progs["bits"], capacity)
            _bind(a, None)
            progs["bits"].run(group_x=self.groups)
            ctx.memory_barrier()
        self._set(progs["plan"], capacity)
        progs["plan"].run(group_x=1)
        ctx.memory_barrier()
        for slot in range(self.slots):
            src = a if slot == 0 else (b if slot % 2 else c)   # what slot - 1 wrote mid-sort
            mid = b if slot % 2 == 0 else c
            from_pairs = pairs and slot > 0
            _bind(src, None)
            self._run(self._program("count", from_pairs), state, args["pass"], slot, capacity)
            ctx.memory_barrier()
            self._run(progs["scan"], state, args["scan"], slot, capacity)
            ctx.memory_barrier()
            _bind(src, mid)
            self._run(self._program("scatter", from_pairs, pairs), state, args["mid"], slot,
                      capacity)
            if slot:  # the last of several passes writes A (slot 0 never is)
                _bind(src, a)
                self._run(self._program("scatter", from_pairs), state, args["last"], slot,
                          capacity)
            ctx.memory_barrier()
        _bind(b, a)
        self._run(self._program("copy", pairs), state, args["copy"], 0, capacity)
        ctx.memory_barrier()

    @staticmethod
    def _set(prog, capacity: int) -> None:
        if "u_capacity" in prog:
            prog["u_capacity"].value = capacity

    def _run(self, prog, state, offset: int, slot: int, capacity: int) -> None:
        self._set(prog, capacity)
        if "u_slot" in prog:
            prog["u_slot"].value = slot
        prog.run_indirect(state, offset + 16 * slot)


def pair_bytes(capacity: int) -> int:
    """Bytes of a pair buffer for ``capacity`` keys (8 a key, in whole groups of 4 keys)."""
    return 32 * -(-capacity // 4)


def _bind(src, dst) -> None:
    """Bind a set of buffers (keys and values, or one pair buffer) as the input and ``dst``
    as the output."""
    for buf, point in zip(src, (RADIX_BINDING_KEYS_IN, RADIX_BINDING_VALS_IN)):
        buf.bind_to_storage_buffer(point)
    if dst is not None:
        for buf, point in zip(dst, (RADIX_BINDING_KEYS_OUT, RADIX_BINDING_VALS_OUT)):
            buf.bind_to_storage_buffer(point)
