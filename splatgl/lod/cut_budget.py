"""A splat budget's cut: the finest cut through a level-of-detail tree that draws at most
``budget`` nodes, its threshold searched on a log scale (a cut's count falls roughly as the
threshold squared) with trial cuts (:func:`splatgl.lod.cut.select_cut_weights`), each abandoned
past a few times the budget so a search's memory stays a few budgets' at any tree size;
:func:`select_cut_budget_near` starts from a nearby view's threshold (the viewer's last frame).
"""

from __future__ import annotations

import numpy as np

from ..cameras.camera import Camera
from .cut import DEFAULT_THRESHOLD_PX, CutData, CutTooLarge, select_cut_weights

#: Budget search: at most this many cuts per view, stopping within this fraction of the budget.
BUDGET_STEPS = 8
BUDGET_TOLERANCE = 0.1
#: Where no cut fitted within BUDGET_STEPS: at most this many more (doubling the threshold),
#: then this many narrowing steps between the last cut too large and the first that fits.
MAX_LATE_STEPS = 40
LATE_BISECTIONS = 3
#: A budget's search abandons a trial cut past this many times the budget (CutTooLarge), so
#: its memory stays a few budgets' at any size, and steps as if the cut held that many.
ABORT_FACTOR = 3
#: The search from a nearby view's threshold (:func:`select_cut_budget_near`): at most this many
#: cuts, stepping the threshold by at least this factor until the budget is bracketed.
NEAR_STEPS = 6
NEAR_FACTOR = 1.15


def select_cut_budget(data: CutData, camera: Camera, budget: int,
                      threshold_px: float = DEFAULT_THRESHOLD_PX, band: float = 1.0, kern=None
                      ) -> tuple[np.ndarray, np.ndarray | None, float]:
    """The finest cut of at most ``budget`` drawn nodes, not finer than ``threshold_px``:
    ``(node rows, weights, threshold used)`` (rows and weights as :func:`select_cut_weights`
    gives them for that threshold and ``band``).  The threshold is searched on a log scale (a
    cut's count falls roughly as the threshold squared), BUDGET_STEPS cuts at most; it changes
    from view to view, so a budget's cut is not continuous along a path, band or not.
    ``kern`` as :func:`select_cut_weights` takes it.  A trial cut past ABORT_FACTOR times the
    budget is abandoned (:class:`CutTooLarge`) and counts as that many nodes."""
    ok = None
    lo, hi = threshold_px, None  # lo: known too many nodes (or the floor), hi: known to fit
    t = threshold_px
    first_fit = None  # the step of the first cut that fitted
    for step in range(BUDGET_STEPS + MAX_LATE_STEPS):
        cut, w, size = _trial_cut(data, camera, t, band, kern, budget)
        if size <= budget:
            ok, hi = (cut, w, t), t
            first_fit = step if first_fit is None else first_fit
            if t <= threshold_px or size >= (1.0 - BUDGET_TOLERANCE) * budget:
                break
        else:
            lo = t
        # Out of steps: stop.  Where no cut fitted yet (leaves larger than the threshold keep
        # the count high, so it falls far slower than the threshold squared), keep doubling the
        # threshold until one does, then narrow that last bracket LATE_BISECTIONS times.
        if first_fit is not None and step >= max(BUDGET_STEPS, first_fit + LATE_BISECTIONS + 1) - 1:
            break
        if hi is None:
            t = t * (2.0 if step + 1 >= BUDGET_STEPS else max(1.25, float(np.sqrt(size / budget))))
        else:
            t = float(np.sqrt(lo * hi))
    if ok is None:  # even the coarsest threshold tried was too fine: the root level's cut
        ok = (*select_cut_weights(data, camera, float("inf"), band, kern=kern), float("inf"))
    return ok


def _trial_cut(data: CutData, camera: Camera, t: float, band: float, kern, budget: int):
    """``(rows, weights, nodes)`` of a budget search's trial at ``t`` (rows None: abandoned)."""
    try:
        cut, w = select_cut_weights(data, camera, t, band, kern=kern,
                                    max_nodes=ABORT_FACTOR * int(budget))
    except CutTooLarge:
        return None, None, ABORT_FACTOR * int(budget) + 1
    return cut, w, int(cut.size)


def select_cut_budget_near(data: CutData, camera: Camera, budget: int, start: float,
                           threshold_px: float = DEFAULT_THRESHOLD_PX, band: float = 1.0, kern=None,
                           steps: int = NEAR_STEPS) -> tuple[np.ndarray, np.ndarray | None, float]:
    """:func:`select_cut_budget` searched from ``start``, the threshold of a view nearby (the
    last frame's): consecutive frames need about the same threshold, so two or three cuts
    usually settle it where the search from the floor takes a dozen.  Steps by the ratio of the
    count to the budget (at least NEAR_FACTOR) until bracketed, then halves the bracket on a log
    scale; where ``steps`` cuts find none that fits, the search from the floor decides."""
    ok = None
    lo = hi = None
    t = max(float(start), threshold_px) if np.isfinite(start) else threshold_px
    for _ in range(steps):
        cut, w, size = _trial_cut(data, camera, t, band, kern, budget)
        if size <= budget:
            ok, hi = (cut, w, t), t
            if t <= threshold_px or size >= (1.0 - BUDGET_TOLERANCE) * budget:
                break
        else:
            lo = t
        if hi is None:
            t *= max(NEAR_FACTOR, size / budget)
        elif lo is None:
            t = max(threshold_px, t / max(NEAR_FACTOR, float(np.sqrt(budget / max(size, 1)))))
        else:
            t = float(np.sqrt(lo * hi))
    if ok is None:
        return select_cut_budget(data, camera, budget, threshold_px, band, kern)
    return ok

