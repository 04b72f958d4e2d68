"""Optional compiled kernels (numba, the ``fast`` extra), loaded in the background so that
nothing waits for them.  This module is the loader only: it knows no kernel.  A kernel module
(``splatgl.order._numba_cull``: the chunked cull of a pinhole view ``view_pass``, a lens
camera's ``lens_pass``, a LOD cut's rows in place ``rows_pass``; ``splatgl.lod._cut_numba``: the
LOD cut's selection ``cut_level``) is named to it with :func:`register` by the module that uses
its kernels, so that the order stage never imports the layers above it; a kernel module
provides ``KERNELS`` (the names it hands out) and ``warm_up()`` (compiles them).

With NumPy these pay a few microseconds per call: a view from inside a scene splits into
hundreds of runs of kept chunks plus a gathered per-row test of the boundary chunks, and a cut
walks its levels in a dozen array passes each, so at 1M splats the cull cost more than the sort
(docs/scale.md).  One compiled loop does the same float32 operations without the calls.
Importing numba and compiling the four kernels takes about 9 s the first time on this machine,
then about 1 s from numba's on-disk cache, so :func:`request` starts that on a daemon thread
and :func:`kernel` hands them out only once they are ready: until then, and wherever numba is
missing, the NumPy paths run.  Both give the same keys and cuts, bit for bit
(tests/order/test_cull_chunks.py, tests/lod/test_lod_blend.py), so switching between them mid-session
changes no image.
"""

from __future__ import annotations

import importlib
import importlib.util
import os
from concurrent.futures import ThreadPoolExecutor
from types import SimpleNamespace

from ..background import Background

#: The registered kernel modules (dotted names), in registration order.
_modules: list[str] = []
#: Each requested module's load; one load covers the modules registered by the time it starts.
_loads: dict[str, Background] = {}
_requested = False
#: The kernels of the last complete set of loads, with the loads they came from.
_merged: tuple[tuple[Background, ...], SimpleNamespace] | None = None
_helper: ThreadPoolExecutor | None = None
#: How chunked culls that do not say otherwise (``ChunkedCull.compiled`` None) use the kernel:
#: "auto" once loaded (from the second view on), "off" never, "wait" always (waiting for the
#: load).  Set with :func:`set_policy` (the benchmark measures both paths this way).
POLICIES = ("auto", "off", "wait")
_policy = "auto"
#: From this culled view on, the kernels are loaded in the background: a one-frame render never
#: pays numba's import, a path or the viewer switch to them a few frames in.
FROM_VIEW = 2


def installed() -> bool:
    """numba is importable (the ``fast`` extra)."""
    return importlib.util.find_spec("numba") is not None


def register(module: str) -> None:
    """Name a kernel module (dotted name) for the background load: it is imported on the
    loader's thread, its ``warm_up()`` run and its ``KERNELS`` handed out by :func:`kernel`.
    Registering after the load was requested starts a load of the new module, and
    :func:`kernel` gives None (the NumPy paths) until that one is ready too."""
    if module in _modules:
        return
    _modules.append(module)
    if _requested:
        _start()


def _load(modules: tuple[str, ...]) -> dict[str, object]:
    found: dict[str, object] = {}
    for name in modules:
        mod = importlib.import_module(name)
        mod.warm_up()
        found.update((k, getattr(mod, k)) for k in mod.KERNELS)
    return found


def _start() -> None:
    pending = tuple(m for m in _modules if m not in _loads)
    if pending:
        load = Background(_load, pending, name="splatgl-cull-kernel")
        _loads.update((m, load) for m in pending)


def request() -> None:
    """Start loading the registered kernels in the background (each module once per process;
    nothing without numba)."""
    global _requested
    if installed():
        _requested = True
        _start()


def kernel(wait: bool = False):
    """The compiled kernels of every registered module (``view_pass``, ``rows_pass`` and
    ``lens_pass`` of :mod:`splatgl.order._numba_cull`, ``cut_level`` of
    :mod:`splatgl.lod._cut_numba`, as attributes) if they are all loaded (``wait``: after
    waiting for the loads that :func:`request` started, starting them if needed), else None; a
    failed load, or no module registered, gives None."""
    global _merged
    if wait:
        request()
    if not _modules or any(m not in _loads for m in _modules):
        return None
    loads = tuple(dict.fromkeys(_loads[m] for m in _modules))
    if not wait and not all(load.done() for load in loads):
        return None
    if _merged is not None and _merged[0] == loads:
        return _merged[1]
    try:
        found = [load.result() for load in loads]
    except Exception:  # a broken numba install: the NumPy path serves
        return None
    _merged = (loads, SimpleNamespace(**{k: v for part in found for k, v in part.items()}))
    return _merged[1]


def for_view(views: int, compiled: bool | None = None):
    """The kernels for a cull's ``views``-th view (counting from 1), or None for the NumPy
    path: ``compiled`` False never, True always (waiting for the load), None as :func:`policy`
    says (by default once loaded, requested from view :data:`FROM_VIEW` on)."""
    mode = compiled
    if mode is None:
        mode = {"auto": None, "off": False, "wait": True}[_policy]
    if mode is False:
        return None
    if mode or views >= FROM_VIEW:
        request()
    return kernel(wait=bool(mode))


def set_policy(policy: str) -> None:
    """Set the process-wide policy (one of :data:`POLICIES`)."""
    global _policy
    if policy not in POLICIES:
        raise ValueError(f"cull kernel policy must be one of {', '.join(POLICIES)}, got {policy!r}")
    _policy = policy


def policy() -> str:
    return _policy


def helper() -> ThreadPoolExecutor | None:
    """One worker thread that runs part of a view's compiled pass while the calling thread runs
    the rest (the kernel releases the GIL); None on a machine with a single core."""
    global _helper
    if _helper is None and len(os.sched_getaffinity(0)) > 1:
        _helper = ThreadPoolExecutor(max_workers=1, thread_name_prefix="splatgl-cull")
    return _helper


def _after_fork_in_child() -> None:
    """A forked child has none of its parent's threads: the helper thread is made anew on
    demand, and a load still under way in the parent is started again when requested."""
    global _helper
    _helper = None
    for module, load in list(_loads.items()):
        if not load.done():
            del _loads[module]


os.register_at_fork(after_in_child=_after_fork_in_child)
