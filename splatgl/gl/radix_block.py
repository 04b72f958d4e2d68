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
  and no subgroup operation.

The passes run over only the bits in which keys differ, planned on the device
(``radix_plan.comp`` with ``RADIX_BLOCK``; ``radix_block_bits.comp`` finds the bits), with
indirect dispatches: nothing is read back.  Pass s reads A (s = 0) or what pass s - 1 wrote and
writes B (s even) or C (s odd), except that the last of several passes writes A; after a single
pass ``radix_block_copy.comp`` brings B into A.  The host records every slot's dispatches with
the buffers that slot would use and the plan gives the slots the keys do not need no work
groups.
"""

from __future__ import annotations

import os

import moderngl

from ..constants import RADIX_BLOCK_BITS
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


def block_groups() -> int:
    """Work groups of a block pass: two a CPU thread of the software rasteriser (``LP_NUM_THREADS``
    or the cores), so the threads share the work however the OS schedules them."""
    try:
        threads = int(os.environ.get(THREADS_ENV, ""))
    except ValueError:
        threads = os.cpu_count() or 1
    return max(2, min(MAX_GROUPS, 2 * max(1, threads)))


class BlockPasses:
    """The programs of the block passes for ``groups`` work groups, and the recording of a
    sort (:meth:`record`) into the buffers a :class:`~splatgl.gl.radix_sort.RadixSorter`
    holds."""

    NAMES = ("bits", "plan", "count", "scan", "scatter", "copy")

    def __init__(self, programs: ProgramCache, groups: int | None = None,
                 bits: int = RADIX_BLOCK_BITS):
        self.groups = groups or block_groups()
        self.lanes = self.groups * RADIX_BLOCK_LANES
        self.bits = bits
        self.slots = -(-32 // bits)
        defines = {"RADIX_BLOCK": 1, "RADIX_BLOCK_GROUPS": self.groups, "RADIX_BLOCK_BITS": bits}
        self.programs = {name: programs.compute(f"radix_{'block_' if name != 'plan' else ''}{name}.comp",
                                                defines)
                         for name in self.NAMES}

    def hist_bytes(self) -> int:
        """Bytes of hist: a row of digit counts a lane, then the digit starts."""
        return 4 * (self.lanes + 1) * (1 << self.bits)

    def record(self, ctx: moderngl.Context, state: moderngl.Buffer, sets, hist, capacity: int,
               find_bits: bool, args: dict[str, int]) -> None:
        """Dispatch a sort of the A keys (the count is in ``state``): ``sets`` the (keys,
        values) buffers A, B, C of ``capacity`` keys; ``find_bits``: run the bits kernel first
        (the state holds no OR/AND yet); ``args``: byte offsets in ``state`` of the indirect
        arguments by name (pass, scan, mid, last: per slot, 16 bytes each; copy)."""
        progs = self.programs
        for prog in progs.values():
            if "u_capacity" in prog:
                prog["u_capacity"].value = capacity
        a, b, c = sets
        hist.bind_to_storage_buffer(RADIX_BINDING_HIST)
        if find_bits:
            _bind(a, None)
            progs["bits"].run(group_x=self.groups)
            ctx.memory_barrier()
        progs["plan"].run(group_x=1)
        ctx.memory_barrier()
        for slot in range(self.slots):
            src = a if slot == 0 else (b if slot % 2 else c)   # what slot - 1 wrote mid-sort
            mid = b if slot % 2 == 0 else c
            for name in ("count", "scatter"):
                progs[name]["u_slot"].value = slot
            _bind(src, None)
            progs["count"].run_indirect(state, args["pass"] + 16 * slot)
            ctx.memory_barrier()
            progs["scan"].run_indirect(state, args["scan"] + 16 * slot)
            ctx.memory_barrier()
            _bind(src, mid)
            progs["scatter"].run_indirect(state, args["mid"] + 16 * slot)
            if slot:  # the last of several passes writes A (slot 0 never is)
                _bind(src, a)
                progs["scatter"].run_indirect(state, args["last"] + 16 * slot)
            ctx.memory_barrier()
        _bind(b, a)
        progs["copy"].run_indirect(state, args["copy"])
        ctx.memory_barrier()


def _bind(src, dst) -> None:
    src[0].bind_to_storage_buffer(RADIX_BINDING_KEYS_IN)
    src[1].bind_to_storage_buffer(RADIX_BINDING_VALS_IN)
    if dst is not None:
        dst[0].bind_to_storage_buffer(RADIX_BINDING_KEYS_OUT)
        dst[1].bind_to_storage_buffer(RADIX_BINDING_VALS_OUT)
