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
