"""Optional compiled kernels (numba, the ``fast`` extra), loaded in the background so that
nothing waits for them: the chunked cull of a pinhole view (``view_pass``), the cull of a lens
camera's view (``lens_pass``), the cull of a LOD cut's rows in place (``rows_pass``) and the
LOD cut's selection (``cut_pass``).

With NumPy these pay a few microseconds per call: a view from inside a scene splits into
hundreds of runs of kept chunks plus a gathered per-row test of the boundary chunks, and a cut
walks its levels in a dozen array passes each, so at 1M splats the cull cost more than the sort
(docs/scale.md).  One compiled loop does the same float32 operations without the calls.
Importing numba and compiling the four kernels takes about 9 s the first time on this machine,
then about 1 s from numba's on-disk cache, so :func:`request` starts that on a daemon thread
and :func:`kernel` hands them out only once they are ready: until then, and wherever numba is
missing, the NumPy paths run.  Both give the same keys and cuts, bit for bit
(tests/test_cull_chunks.py, tests/test_lod_blend.py), so switching between them mid-session
changes no image.
"""

from __future__ import annotations

import importlib.util
import os
from concurrent.futures import ThreadPoolExecutor
from types import SimpleNamespace

from ..background import Background

_loader: Background | None = None
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


def _load():
    from . import _numba_cull as _cull_numba
    from ..lod import _cut_numba

    _cull_numba.warm_up()
    _cut_numba.warm_up()
    return SimpleNamespace(view_pass=_cull_numba.view_pass, rows_pass=_cull_numba.rows_pass,
                           lens_pass=_cull_numba.lens_pass, cut_pass=_cut_numba.cut_pass)


def request() -> None:
    """Start loading the kernel in the background (once per process; nothing without numba)."""
    global _loader
    if _loader is None and installed():
        _loader = Background(_load, name="splatgl-cull-kernel")


def kernel(wait: bool = False):
    """The compiled kernels (``view_pass``, ``rows_pass`` and ``lens_pass`` of
    :mod:`splatgl.order._numba_cull`, ``cut_pass`` of :mod:`splatgl.lod._cut_numba`) if they are
    loaded (``wait``: after waiting for the load that :func:`request` started, starting it if
    needed), else None; a failed load gives None."""
    if wait:
        request()
    if _loader is None or not (wait or _loader.done()):
        return None
    try:
        return _loader.result()
    except Exception:  # a broken numba install: the NumPy path serves
        return None


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
    global _helper, _loader
    _helper = None
    if _loader is not None and not _loader.done():
        _loader = None


os.register_at_fork(after_in_child=_after_fork_in_child)
