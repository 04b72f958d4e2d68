"""Will a scene fit?  Checked from a file's header, before its arrays are allocated.

A file too big for the memory that is left would otherwise fail deep inside NumPy (or get the
process killed by the kernel) after minutes of reading; this turns it into one line naming the
file, what it needs and what is available.
"""

from __future__ import annotations

import os
from pathlib import Path

from .constants import sh_coeff_count
from .errors import SceneFormatError

#: Overrides the available memory (bytes): tests, and users who want a tighter cap.
LIMIT_ENV = "SPLATGL_MEMORY_LIMIT"
#: CPU bytes per splat the renderers keep beside the scene's own arrays (the cull's
#: per-scene data, :class:`splatgl.cull.CullData`: 3 floats, 3 floats, 2 flags).
RENDER_BYTES_PER_SPLAT = 26


def available_bytes() -> int | None:
    """Memory this process can still allocate: ``$SPLATGL_MEMORY_LIMIT``, else the smaller of
    /proc/meminfo's MemAvailable and the cgroup's remaining limit; None where unknown."""
    env = os.environ.get(LIMIT_ENV)
    if env:
        return int(float(env))
    found = []
    try:
        for line in Path("/proc/meminfo").read_text().splitlines():
            if line.startswith("MemAvailable:"):
                found.append(int(line.split()[1]) * 1024)
    except OSError:
        pass
    try:
        limit = Path("/sys/fs/cgroup/memory.max").read_text().strip()
        used = int(Path("/sys/fs/cgroup/memory.current").read_text().strip())
        if limit != "max":
            found.append(int(limit) - used)
    except (OSError, ValueError):
        pass
    return min(found) if found else None


def scene_bytes(count: int, sh_degree: int, surfel: bool = False) -> int:
    """CPU bytes of a loaded scene of ``count`` splats: its float32 arrays (means 3, quats 4,
    log-scales 3 or 2, opacity 1, SH 3 per coefficient) plus the renderers' per-splat data."""
    floats = 3 + 4 + (2 if surfel else 3) + 1 + 3 * sh_coeff_count(sh_degree)
    return count * (4 * floats + RENDER_BYTES_PER_SPLAT)


def _size(n: float) -> str:
    return f"{n / 1e9:.2f} GB" if n >= 1e9 else f"{n / 1e6:.1f} MB"


def check_fits(path, count: int, sh_degree: int, surfel: bool = False, extra: int = 0) -> None:
    """Raise :class:`SceneFormatError` if ``count`` splats (plus ``extra`` bytes of reader
    buffers) need more memory than :func:`available_bytes`; silent where that is unknown."""
    need = scene_bytes(count, sh_degree, surfel) + extra
    have = available_bytes()
    if have is not None and need > have:
        raise SceneFormatError(
            path, f"needs {_size(need)} of memory to load {count:,} splats (SH degree {sh_degree}), "
                  f"only {_size(max(have, 0))} available")
