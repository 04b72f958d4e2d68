"""Run stress cases through every renderer and report finiteness, error and time.

Per case: the float64 NumPy reference renders the expected image (``reference64``); the quad
path, the tile renderer, the CPU renderer (where numba is installed) and the float32 reference
render the case.  Each renderer's row says
whether every output (RGBA and the accumulated depth) is finite, its max-abs RGBA error against
the float64 image, the case's bound for it, and the seconds it took.  A row passes when it is
finite, within its bound and under the time limit; a renderer that refuses a case it does not
support, with a clear error, is marked ``unsupported`` (and passes).  A hang is caught by a
watchdog that dumps every thread's stack and exits (:func:`watchdog`).
"""

from __future__ import annotations

import contextlib
import faulthandler
import math
import sys
import time
import traceback
from dataclasses import asdict, dataclass

import numpy as np

from ...errors import SplatglError
from ...reference import render_reference
from ...scene.settings import RendererKind
from .cases import CASES, StressCase

#: The renderers under test, in table order (``cpu`` needs the ``fast`` extra:
#: :func:`default_renderers`).
RENDERERS = ("quad", "tile", "cpu", "reference32")
#: A render slower than this (seconds) fails the case ("no hang", short of a real hang).
TIME_LIMIT_S = 60.0
#: A case still running after this many seconds is a hang: the watchdog exits the process.
HANG_LIMIT_S = 600.0


@dataclass(frozen=True)
class RendererResult:
    """One renderer on one case.  ``status``: ok, fail, known (a failure the case documents as
    understood and not fixed), unsupported or error.

    finite: every RGBA and depth value finite.  max_error: max |RGBA - float64 reference|
    (inf where either is not finite).  depth_error: max |D - D_ref| / max |D_ref| (relative).
    """

    renderer: str
    status: str
    finite: bool | None
    max_error: float | None
    depth_error: float | None
    bound: float
    seconds: float
    message: str = ""

    @property
    def passed(self) -> bool:
        return self.status in ("ok", "unsupported")


@dataclass(frozen=True)
class CaseResult:
    case: str
    what: str
    rows: tuple[RendererResult, ...]

    @property
    def passed(self) -> bool:
        return all(r.passed for r in self.rows)

    def row(self, renderer: str) -> RendererResult:
        return next(r for r in self.rows if r.renderer == renderer)


@contextlib.contextmanager
def watchdog(seconds: float = HANG_LIMIT_S):
    """Exit the process (after dumping every thread's stack to stderr) if the body hangs."""
    faulthandler.dump_traceback_later(seconds, exit=True, file=sys.__stderr__)  # not a capture
    try:
        yield
    finally:
        faulthandler.cancel_dump_traceback_later()


def _layers(renderer: str, setup, gl):
    """(rgba (H, W, 4), depth (H, W)) of one renderer, as float64 arrays."""
    if renderer == "reference32":
        ref = render_reference(setup.scene, setup.camera, setup.settings, np.float32)
        rgba = np.concatenate([ref.color, ref.alpha[..., None]], -1)
        return rgba, ref.depth
    kind = RendererKind(renderer)
    out = gl.render_layers(setup.scene, setup.camera, setup.settings, kind)
    return out.rgba, out.depth


def _max_abs(got: np.ndarray, want: np.ndarray) -> float:
    """Largest |got - want|, inf if any value of either is not finite (chunked: 8192^2 images)."""
    worst = 0.0
    for g, w in zip(np.array_split(got, max(1, got.shape[0] // 512)),
                    np.array_split(want, max(1, want.shape[0] // 512))):
        d = np.abs(g.astype(np.float64) - w)
        if not np.isfinite(d).all():
            return math.inf
        worst = max(worst, float(d.max(initial=0.0)))
    return worst


def _row(renderer: str, case: StressCase, setup, gl, want_rgba, want_depth) -> RendererResult:
    bound = case.bounds.of(renderer)
    t0 = time.perf_counter()
    try:
        rgba, depth = _layers(renderer, setup, gl)
    except Exception as exc:  # noqa: BLE001 -- every failure becomes a row of the report
        seconds = time.perf_counter() - t0
        message = f"{type(exc).__name__}: {exc}"
        if renderer in case.unsupported and isinstance(exc, (SplatglError, NotImplementedError)):
            return RendererResult(renderer, "unsupported", None, None, None, bound, seconds, message)
        return RendererResult(renderer, "error", None, None, None, bound, seconds,
                              message + "\n" + traceback.format_exc(limit=3))
    seconds = time.perf_counter() - t0
    finite = bool(np.isfinite(rgba).all() and np.isfinite(depth).all())
    err = _max_abs(rgba, want_rgba)
    scale = float(np.abs(want_depth).max(initial=0.0)) or 1.0
    depth_err = _max_abs(depth, want_depth) / scale
    problems = []
    if not finite:
        problems.append(f"non-finite output ({int((~np.isfinite(rgba)).any(-1).sum())} RGBA pixels)")
    if not err <= bound:
        problems.append(f"error {err:.3g} > bound {bound:.3g}")
    if seconds > TIME_LIMIT_S:
        problems.append(f"took {seconds:.1f} s > {TIME_LIMIT_S:.0f} s")
    status = "fail" if problems else "ok"
    if problems and renderer in case.known:
        status = "known"
        problems.append("known: " + case.known[renderer])
    return RendererResult(renderer, status, finite, err, depth_err, bound, seconds,
                          "; ".join(problems))


def default_renderers() -> tuple[str, ...]:
    """:data:`RENDERERS` less ``cpu`` where numba is not installed."""
    from ...renderers.registry import installed, names

    return tuple(r for r in RENDERERS if r not in names() or installed(r))


def run_case(case: StressCase, gl=None, renderers=None) -> CaseResult:
    """Render ``case`` with each of ``renderers`` and the float64 reference; see the module doc.

    ``gl``: a :class:`splatgl.api.Renderer` (one is made, and closed, when None and a GPU
    renderer is asked for).  ``renderers``: default :func:`default_renderers`.
    """
    renderers = default_renderers() if renderers is None else renderers
    setup = case.build()
    truth = setup.expected_scene if setup.expected_scene is not None else setup.scene
    t0 = time.perf_counter()
    ref = render_reference(truth, setup.camera, setup.settings, np.float64)
    ref_seconds = time.perf_counter() - t0
    want_rgba = np.concatenate([ref.color, ref.alpha[..., None]], -1)
    want_depth = ref.depth
    del ref
    ref_finite = bool(np.isfinite(want_rgba).all() and np.isfinite(want_depth).all())
    rows = [RendererResult("reference64", "ok" if ref_finite else "fail", ref_finite, 0.0, 0.0,
                           0.0, ref_seconds, "" if ref_finite else "non-finite truth")]
    own = None
    if gl is None and any(r != "reference32" for r in renderers):
        from ...api import Renderer
        gl = own = Renderer()
    try:
        for renderer in renderers:
            rows.append(_row(renderer, case, setup, gl, want_rgba, want_depth))
    finally:
        if own is not None:
            own.close()
    return CaseResult(case.name, case.what, tuple(rows))


def run_cases(cases=CASES, renderers=None, progress=None) -> list[CaseResult]:
    """Run ``cases`` in order, each under the hang watchdog, each with a fresh GL renderer."""
    results = []
    for case in cases:
        if progress is not None:
            progress(case)
        with watchdog():
            results.append(run_case(case, None, renderers))
    return results


def _fmt(value: float | None) -> str:
    if value is None:
        return "-"
    if math.isinf(value):
        return "inf"
    return f"{value:.2e}" if value else "0"


def format_table(results: list[CaseResult]) -> str:
    """The report table: case, renderer, finite?, max error, bound, pass/fail, seconds."""
    head = ("case", "renderer", "finite", "max error", "bound", "result", "seconds")
    lines = [head]
    for res in results:
        for r in res.rows:
            finite = "-" if r.finite is None else ("yes" if r.finite else "NO")
            result = {"ok": "pass", "unsupported": "n/a", "known": "KNOWN"}.get(r.status, "FAIL")
            lines.append((res.case, r.renderer, finite, _fmt(r.max_error),
                          _fmt(r.bound) if r.renderer != "reference64" else "truth", result,
                          f"{r.seconds:.2f}"))
    widths = [max(len(row[i]) for row in lines) for i in range(len(head))]
    out = ["  ".join(c.ljust(w) for c, w in zip(row, widths)).rstrip() for row in lines]
    out.insert(1, "  ".join("-" * w for w in widths))
    notes = [f"  {res.case}/{r.renderer}: {r.message.splitlines()[0]}"
             for res in results for r in res.rows if r.message]
    return "\n".join(out + (["", "notes:"] + notes if notes else []))


def format_report(results: list[CaseResult], fixes=None) -> str:
    """The table, the bound notes and the list of fixes (what failed before each)."""
    from .cases import BOUND_NOTES
    from .fixes import FIXES
    fixes = FIXES if fixes is None else fixes
    lines = [format_table(results), "", "bounds (max |RGBA error| against the float64 reference):"]
    lines += [f"  {k}: {v}" for k, v in BOUND_NOTES.items()]
    lines += ["", "fixes (guards in the renderers; what failed before each):"]
    for fix in fixes:
        lines.append(f"  - {fix.title}  [{fix.where}]")
        lines += [f"      before: {b}" for b in fix.before]
    passed = sum(r.passed for r in results)
    known = sum(1 for res in results for r in res.rows if r.status == "known")
    lines += ["", f"{passed} of {len(results)} cases passed"
              + (f" ({known} known, unfixed failure(s) listed in the notes)" if known else "")]
    return "\n".join(lines)


def results_json(results: list[CaseResult], fixes=None) -> dict:
    """The report as plain data (``splatgl stress --json``)."""
    from .fixes import FIXES
    fixes = FIXES if fixes is None else fixes

    def clean(v):
        return None if isinstance(v, float) and not math.isfinite(v) else v

    return {
        "cases": [{"case": r.case, "what": r.what, "passed": r.passed,
                   "rows": [{k: clean(v) for k, v in asdict(row).items()} for row in r.rows]}
                  for r in results],
        "fixes": [asdict(f) for f in fixes],
    }
