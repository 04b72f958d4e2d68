"""The out-of-core build's memory budget (``splatgl lod --memory SIZE``): parsing a size, the
default (a fraction of this machine's RAM) and how the budget is shared out.

The budget bounds the whole process's peak resident memory.  What the interpreter and its
libraries already hold when the build starts (measured) and a reserve are taken off first; the
rest is the working memory, from which the chunk sizes are chosen (:func:`plan`).
"""

from __future__ import annotations

import os
import re
import resource
import sys
from dataclasses import dataclass

from ..errors import SplatglError

#: The default budget: this fraction of the machine's RAM.
DEFAULT_FRACTION = 0.5
#: Working memory below this (after what the process already holds) is refused.
MIN_WORKING = 24 << 20
#: Held back from the working memory: what the build's own imports, buffers and the allocator
#: add beyond the arrays it plans for (measured: 5-8 MiB over a 120 MiB budget without it).
RESERVE = 16 << 20
#: Bytes of working memory per leaf of a chunk's subtree while it is built (float64 moments,
#: covariances and SH with their temporaries, the decoded leaves and the rows written),
#: plus this many times the input's record size.
PER_LEAF = 900
PER_RECORD = 4
_UNITS = {"": 1, "b": 1, "k": 1 << 10, "kb": 1 << 10, "kib": 1 << 10, "m": 1 << 20, "mb": 1 << 20,
          "mib": 1 << 20, "g": 1 << 30, "gb": 1 << 30, "gib": 1 << 30, "t": 1 << 40,
          "tb": 1 << 40, "tib": 1 << 40}
_SIZE = re.compile(r"^\s*([0-9]+(?:\.[0-9]*)?|\.[0-9]+)\s*([a-zA-Z]*)\s*$")


def parse_size(text: str, option: str = "--memory") -> int:
    """Bytes of a size such as ``200M``, ``1.5G``, ``4GiB`` or ``300000000`` (K, M, G, T are
    powers of 1024); anything else is one line naming ``option`` and the value."""
    match = _SIZE.match(str(text))
    unit = match.group(2).lower() if match else None
    if match is None or unit not in _UNITS:
        raise SplatglError(f"{option}: expected a size such as 200M, 1.5G or 4GiB, got {text!r}")
    value = float(match.group(1)) * _UNITS[unit]
    if not value >= 1:
        raise SplatglError(f"{option}: the size must be positive, got {text!r}")
    return int(value)


def format_size(n: float) -> str:
    """``"1.5 GiB"``, ``"200 MiB"``: a byte count for messages."""
    for unit, scale in (("TiB", 1 << 40), ("GiB", 1 << 30), ("MiB", 1 << 20), ("KiB", 1 << 10)):
        if n >= scale:
            return f"{n / scale:.3g} {unit}"
    return f"{int(n)} B"


def machine_memory() -> int:
    """Bytes of RAM of this machine (0 where the system does not say)."""
    try:
        return int(os.sysconf("SC_PHYS_PAGES")) * int(os.sysconf("SC_PAGE_SIZE"))
    except (ValueError, OSError, AttributeError):
        return 0


def default_budget() -> tuple[int, str]:
    """``(bytes, how it was chosen)``: DEFAULT_FRACTION of this machine's RAM (4 GiB where the
    system does not say)."""
    ram = machine_memory()
    if ram <= 0:
        return 4 << 30, "4 GiB (this system does not report its RAM)"
    budget = int(ram * DEFAULT_FRACTION)
    return budget, (f"{format_size(budget)} ({DEFAULT_FRACTION:.0%} of this machine's "
                    f"{format_size(ram)} RAM; --memory SIZE to change)")


def budget_from(text: str | None) -> tuple[int, str]:
    """``(bytes, what to print)`` of ``--memory`` (None: :func:`default_budget`)."""
    if text is None:
        return default_budget()
    n = parse_size(text)
    return n, f"{format_size(n)} (--memory)"


def resident_now() -> int:
    """Bytes this process holds resident now (its peak so far where /proc is missing)."""
    try:
        with open("/proc/self/statm") as fh:
            return int(fh.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")
    except (OSError, ValueError, IndexError):
        peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
        return peak if sys.platform == "darwin" else peak * 1024


@dataclass(frozen=True)
class Plan:
    """How a build shares its budget: ``working`` bytes; ``window`` leaves per chunk (a power of
    the branching, so chunks are whole subtrees); ``rows`` per read block; ``run`` rows a sorted
    run may hold."""

    budget: int
    working: int
    window: int
    rows: int
    run: int


def plan(budget: int, branching: int, record_bytes: int, count: int,
         held: int | None = None) -> Plan:
    """The chunk sizes within ``budget`` for ``count`` leaves of ``record_bytes`` each in the
    input; ``held``: bytes the process holds already (measured when None).  A budget that
    leaves less than MIN_WORKING is one line saying what would do."""
    held = resident_now() if held is None else held
    working = budget - held - RESERVE
    if working < MIN_WORKING:
        raise SplatglError(f"--memory {format_size(budget)} is too small: this process already "
                           f"holds {format_size(held)}; give at least "
                           f"{format_size(held + RESERVE + MIN_WORKING)}")
    per_leaf = PER_LEAF + PER_RECORD * record_bytes
    # a third each: the chunk being built, the sorted run feeding it, blocks and the rest
    window = 1
    while window * branching * per_leaf <= working // 3 and window < count:
        window *= branching
    run_bytes = 2 * (record_bytes + 16) + 16
    run = max(working // 3 // run_bytes, 1024)
    rows = int(max(min(working // 12 // (record_bytes + 64), 1 << 16), 256))
    return Plan(budget, working, window, rows, run)


# ------------------------------------------------------------------ a streamed frame's budget
#: Bytes of the CPU side per splat a streamed frame draws, beyond its SH and GPU storage: the
#: gathered scene's means, quaternions, scales and opacity (44), the cut's rows and weights
#: (12), the selection's sphere reads (32: freed before the frame's arrays, so headroom),
#: the cull's data (20), the order's scratch (indices, keys, their sort and the order: 36) and
#: the allocator's slack (20).  The SH adds 12 bytes a coefficient (float32 RGB).
FRAME_CPU_BYTES = 164
FRAME_SH_BYTES = 12
#: Bytes of the renderer's per-frame GPU buffers per splat besides the scene's storage
#: (:func:`splatgl.gl.storage.gpu_bytes_per_splat`): the pre-pass's prepared quad (64), the
#: sorted rows and weights (8), early termination's survivors and commands (8).  On a software
#: driver (llvmpipe) these live in the process too.
FRAME_GPU_BYTES = 80
#: Held back from a streamed frame's budget for what does not grow with the cut: the driver's
#: draw of one batch (at most a million splats a draw), its compiled shaders and the targets.
DRAW_RESERVE = 320 << 20
#: The chunk cache's share of the working memory (the rest is the frame's); at least what the
#: resident set needs (its pinned top levels and the chunks in flight).
CACHE_SHARE = 0.2
#: A budget whose frame holds fewer splats than this is refused.
MIN_FRAME_SPLATS = 100


def frame_bytes_per_splat(sh_coeffs: int, gpu_bytes: int) -> int:
    """Bytes of the whole process per splat a streamed frame draws: the CPU side
    (FRAME_CPU_BYTES + FRAME_SH_BYTES per SH coefficient), the scene's GPU storage
    ``gpu_bytes`` and the renderer's per-frame buffers (FRAME_GPU_BYTES)."""
    return FRAME_CPU_BYTES + FRAME_SH_BYTES * int(sh_coeffs) + int(gpu_bytes) + FRAME_GPU_BYTES


#: Bytes the CPU renderer (``--renderer cpu``) holds per splat of a streamed cut beyond the
#: gathered nodes: its float32 inputs (R S, opacity), the projection's per-splat outputs (means,
#: conics, colours, depths, boxes, rectangles), the depth order and the packed records; a
#: streamed cut is projected whole (no cull data).  It uploads nothing, so the gathered nodes
#: stay held (in FRAME_CPU_BYTES) and no GPU storage or per-frame GPU buffers are counted.
#: Measured on the 5M tiled scene's capped default view (3.25M nodes, 1280x720, VmHWM): 360 B a
#: node for the whole process beyond what it held before and the chunks, under the model's 432.
CPU_RENDERER_BYTES = 256
#: The CPU renderer's draw reserve: its images and the tile lists' slack (no driver draw).
CPU_DRAW_RESERVE = 96 << 20


def cpu_frame_bytes_per_splat(sh_coeffs: int) -> int:
    """Bytes of the whole process per splat a streamed frame drawn by the CPU renderer holds:
    FRAME_CPU_BYTES + FRAME_SH_BYTES per SH coefficient + CPU_RENDERER_BYTES."""
    return FRAME_CPU_BYTES + FRAME_SH_BYTES * int(sh_coeffs) + CPU_RENDERER_BYTES


@dataclass(frozen=True)
class StreamPlan:
    """How a streamed level of detail shares one ``--memory`` budget: ``held`` (what the
    process held before its first frame: interpreter, libraries, the GL context), ``reserve``
    (DRAW_RESERVE), ``cache`` (the chunk cache's bytes), ``frame`` (the frame's bytes) and
    ``per_splat`` (:func:`frame_bytes_per_splat`); :attr:`cap` is the most splats a frame
    draws."""

    budget: int
    held: int
    reserve: int
    cache: int
    frame: int
    per_splat: int

    @property
    def cap(self) -> int:
        return max(1, self.frame // self.per_splat)

    def describe(self) -> str:
        return (f"--memory {format_size(self.budget)}: {format_size(self.held)} held, "
                f"{format_size(self.reserve)} for the draw, {format_size(self.cache)} of chunks, "
                f"{format_size(self.frame)} for the frame (at most {self.cap:,} splats at "
                f"{self.per_splat} B)")


def stream_plan(budget: int, per_splat: int, cache_need: int = 0, held: int | None = None,
                reserve: int = DRAW_RESERVE) -> StreamPlan:
    """The split of ``budget`` for a streamed frame of ``per_splat`` bytes a splat
    (:func:`frame_bytes_per_splat`): ``held`` bytes (measured when None) and ``reserve`` off
    first, then CACHE_SHARE of the rest (at least ``cache_need``) to the chunk cache, the rest
    to the frame.  A budget leaving the frame less than MIN_FRAME_SPLATS is one line."""
    held = resident_now() if held is None else int(held)
    working = int(budget) - held - int(reserve)
    cache = max(int(cache_need), int(CACHE_SHARE * working))
    frame = working - cache
    if frame < MIN_FRAME_SPLATS * per_splat:
        least = held + reserve + max(cache_need + MIN_FRAME_SPLATS * per_splat,
                                     int(MIN_FRAME_SPLATS * per_splat / (1.0 - CACHE_SHARE)) + 1)
        raise SplatglError(f"--memory {format_size(budget)} is too small to stream this level of "
                           f"detail: this process holds {format_size(held)}, the draw needs "
                           f"{format_size(reserve)} and the chunks {format_size(cache_need)}; "
                           f"give at least {format_size(least)}")
    return StreamPlan(int(budget), held, int(reserve), cache, frame, int(per_splat))


#: glibc's mallopt parameter: the size from which allocations are mapped (and unmapped on free).
_M_MMAP_THRESHOLD = -3
#: Arrays of this many bytes or more are mapped of their own by a streaming process (a fixed
#: threshold: glibc otherwise raises it to the largest block freed, after which a frame's
#: freed arrays stay in the heap, resident).
MMAP_THRESHOLD = 1 << 20


def release_freed() -> None:
    """Fix the allocator's mapping threshold at MMAP_THRESHOLD and give freed heap memory back
    to the system (glibc; elsewhere nothing), so memory a frame freed is not counted again."""
    import ctypes
    import ctypes.util

    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
        libc.mallopt(_M_MMAP_THRESHOLD, MMAP_THRESHOLD)
        libc.malloc_trim(0)
    except (OSError, AttributeError):
        pass
