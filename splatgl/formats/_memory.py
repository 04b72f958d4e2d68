"""Refuse a scene that cannot fit in memory, before allocating anything sized by its header.

Every reader calls :func:`check_memory` once it knows the splat count (from a header, before
reading the body): it estimates the bytes the load needs (the decoded :class:`Scene` arrays,
the reader's own working arrays and any file bytes held in memory) and compares them with the
memory available now, so a header claiming 2^31 splats ends in one line naming both figures
instead of a ``MemoryError`` traceback (or the system's out-of-memory killer) halfway through.
"""

from __future__ import annotations

import os
from pathlib import Path

from ..errors import SceneFormatError

#: float32 values per splat in a Scene besides the SH: means 3, quats 4, log-scales 3, opacity 1.
SCENE_FLOATS = 11
#: Bytes per splat of :func:`splatgl.scene.splats.activate`'s temporaries (float64 quaternions).
ACTIVATE_BYTES = 32
#: Environment variable overriding the available-memory figure (bytes), for tests and for
#: users who know better than /proc/meminfo (e.g. to allow swap).
ENV_AVAILABLE = "SPLATGL_MEMORY_AVAILABLE"


def scene_bytes(count: int, sh_coeffs: int) -> int:
    """Bytes of the float32 arrays of a decoded scene of ``count`` splats with ``sh_coeffs``
    SH coefficients per channel (1, 4, 9 or 16)."""
    return count * 4 * (SCENE_FLOATS + 3 * sh_coeffs)


def available_memory() -> int | None:
    """Bytes that can be allocated now without swapping, or None where unknown.

    ``$SPLATGL_MEMORY_AVAILABLE`` if set; else ``MemAvailable`` from ``/proc/meminfo``, lowered
    to the cgroup v2 limit's headroom (``memory.max - memory.current``) where there is one;
    else the free physical pages (``os.sysconf``).
    """
    env = os.environ.get(ENV_AVAILABLE)
    if env:
        return int(float(env))
    figures = []
    try:
        with open("/proc/meminfo") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    figures.append(int(line.split()[1]) * 1024)
                    break
    except (OSError, ValueError, IndexError):
        pass
    try:
        limit = Path("/sys/fs/cgroup/memory.max").read_text().strip()
        if limit != "max":
            used = int(Path("/sys/fs/cgroup/memory.current").read_text())
            figures.append(max(0, int(limit) - used))
    except (OSError, ValueError):
        pass
    if not figures:
        try:
            figures.append(os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE"))
        except (OSError, ValueError, AttributeError):
            return None
    return min(figures)


def _size(n: int) -> str:
    for unit, scale in (("GB", 1e9), ("MB", 1e6), ("kB", 1e3)):
        if n >= scale:
            return f"{n / scale:.1f} {unit}"
    return f"{n} bytes"


def check_memory(path, count: int, sh_coeffs: int, work_bytes_per_splat: int = 0,
                 held_bytes: int = 0, field: str | None = None) -> int:
    """Raise :class:`SceneFormatError` unless loading ``count`` splats fits in memory.

    Args:
        count: splats the header declares.  sh_coeffs: SH coefficients per channel.
        work_bytes_per_splat: the reader's own temporaries per splat beyond the scene arrays
            (each reader states its figure next to its decoding code).
        held_bytes: memory the reader holds besides (the file's bytes, a decompressed body).
        field: the header field that set ``count`` (for the message).
    Returns the estimate in bytes.  The estimate is of the load's peak, not exact; with the
    available memory unknown nothing is refused.
    """
    need = (scene_bytes(count, sh_coeffs) + count * (ACTIVATE_BYTES + work_bytes_per_splat)
            + held_bytes)
    require(path, need, f"{count} splats need", field)
    return need


def require(path, need: int, what: str, field: str | None = None) -> None:
    """Raise :class:`SceneFormatError` ("{what} about N GB of memory ..., but only M GB is
    available") when ``need`` bytes exceed :func:`available_memory`."""
    have = available_memory()
    if have is not None and need > have:
        raise SceneFormatError(
            path, f"{what} about {_size(need)} of memory to load, but only {_size(have)} is "
            f"available (set {ENV_AVAILABLE}=BYTES to override)", field)
