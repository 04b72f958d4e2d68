"""A frame-time budget: how much to draw per frame while the camera moves.

Three levers make a frame cheaper: the render scale (a fraction of the window's pixels, then
upscaled: fragments dominate views of large splats), a splat budget (a level-of-detail cut of
at most that many nodes: llvmpipe's per-quad front end, about a microsecond a quad, dominates
scenes over about 100k splats) and the SH degree.  A :class:`Level` is one choice of the three;
:class:`FrameBudget` picks one per frame.

How it picks: a linear cost model, ``t = fixed + per_splat * splats + per_pixel * pixels``
(:mod:`.costs`: from a prior for a software or a hardware device, rescaled by the first frames,
then tracked by a Kalman filter whose costs drift, so the model follows the view), predicts
each level's time (the exact level's: its measured time where lower); the best level whose
prediction fits ``margin * budget`` is the target, and the first frame's level.  Hysteresis
keeps it from flickering between levels:

- a frame over ``over`` (1.15) times the budget, or a level predicted over ``hold`` (1.05) of it,
  moves down to the target at once (never a visibly slow frame twice in a row);
- a level moves up only after ``patience`` (3) frames in a row whose target is higher (then to
  that target);
- the target must fit ``margin`` (0.95) of the budget, but the level in use is kept up to
  ``hold`` (1.05): noise in the measured times moves predictions inside that dead band without
  moving the level.  (At 0.9 and 1.0 frames came in at 0.8 budgets median: on a 2-core AVX2
  llvmpipe donut moved at 12.6-13.3 fps and 28.3-29.7 dB, at 0.95 and 1.05 at 11.3-11.7 fps
  and 31.9-32.7 dB, p10 9.4-9.5 fps; two alternating rounds);
- frames at one level teach the model little about the others, so where ``patience`` frames in
  a row took under ``probe`` (0.6) of the budget and the model still sees nothing better, the
  next frame probes one level up; a probe that comes out slow goes back at once and that level
  is not probed again for PROBE_BACKOFF frames, doubling with each failure.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from ..errors import SplatglError
from .costs import CostModel

#: Render scales tried, best first (fractions of the window's width and height).  The ones below
#: 0.25 are for fill-bound views on slow machines: on a 2-core AVX2 llvmpipe donut's close rest
#: view took 220 ms at 0.25 even with a 12k cut (a cut's merged splats cover as many pixels),
#: and the frame after an input was that slow (latency 180-200 ms, 95-125 with 0.2 and 0.15).
#: Since drafts keep the full-size footprints (draft_low_pass), all splats at 0.1-0.12 beat any
#: cut there: 24.4-26.0 dB in 83-90 ms, against 18.5 dB for a 12k cut at 0.15 in 75 ms
#: (benchmarks/interactive_levels.py at the flight's 7.5 s view).
SCALES = (1.0, 0.85, 0.7, 0.6, 0.5, 0.42, 0.35, 0.3, 0.25, 0.2, 0.15, 0.12, 0.1)
#: The fewest pixels a lower render scale may draw: 128 x 72, the 1280x720 viewer's lowest
#: scale (0.1).  Smaller outputs skip the scales below it: a 160x120 path preview drew frames
#: of 16x12 pixels at 0.1, blobs once upscaled, where pixels cost little anyway.
MIN_DRAFT_PIXELS = 128 * 72
#: Splat budgets tried below the full scene (only where a level-of-detail tree exists).
BUDGETS = (1_000_000, 600_000, 400_000, 250_000, 160_000, 100_000, 70_000, 50_000, 35_000,
           25_000, 18_000, 12_000)
#: The quality model (:func:`predicted_psnr`), fitted to the PSNR of every level against the
#: exact frame on donut, guitar and biker at 1280x720 (benchmarks/interactive_levels.py,
#: docs/results/interactive-levels-psnr.json): a lower scale adds a squared error of
#: ``SCALE_MSE * (1 / scale - 1) ** SCALE_POWER`` (0.5: about 44.4 dB, 0.3: 38.6), a cut keeping
#: a share of the splats ``CUT_MSE * (1 / share - 1) ** CUT_POWER`` (a third: about 31 dB).  The
#: two overlap (a cut's merged splats are blurred already, so a lower scale costs it little):
#: the larger counts whole, the smaller by ``OVERLAP``.  Median error over the grid: 2.8 dB.
#: (Before drafts drew with the full-size footprints, :func:`~splatgl.cameras.view.draft_low_pass`,
#: the scale's error was 2.2e-4 and 1.47: 36.5 dB at 0.5.)
SCALE_MSE, SCALE_POWER = 3.6e-5, 1.59
CUT_MSE, CUT_POWER = 5e-4, 0.6
OVERLAP = 0.5
#: The scene's correction to the cut's error (:func:`cut_factor_for`): the fitted model is off by
#: +7 dB on donut's cuts and -2 dB on guitar's (merged splats matter more or less per scene).
CUT_FACTOR_RANGE = (0.25, 20.0)
#: Frames before a level whose probe was too slow is probed again (doubling per failure, capped).
PROBE_BACKOFF, PROBE_BACKOFF_MAX = 8, 256
#: The model's ceiling (dB): the exact level.
EXACT_PSNR = 60.0


@dataclass(frozen=True, order=True)
class Level:
    """One choice of the levers.

    Attributes:
        scale: fraction of the window's width and height drawn (then upscaled).
        budget: at most this many splats (a level-of-detail cut), or None: the whole scene.
        sh_degree: cap on the SH degree evaluated, or None: the scene's.
    """

    scale: float = 1.0
    budget: int | None = None
    sh_degree: int | None = None

    @property
    def exact(self) -> bool:
        """Whether this level draws exactly what ``splatgl render`` draws."""
        return self.scale == 1.0 and self.budget is None and self.sh_degree is None

    def describe(self) -> str:
        splats = "all splats" if self.budget is None else f"<= {self.budget:,} splats"
        sh = "" if self.sh_degree is None else f", SH {self.sh_degree}"
        return f"scale {self.scale:.2f}, {splats}{sh}"


#: The level that draws exactly what ``splatgl render`` draws.
EXACT = Level()


def check_fps(fps: float | None) -> float | None:
    """A frame-rate target as given (``--target-fps``): None (the default for the machine), 0 (no
    budget: every frame exact) or a positive finite number; anything else is refused."""
    if fps is None:
        return None
    fps = float(fps)
    if not (0.0 <= fps < math.inf):
        raise SplatglError(f"--target-fps must be 0 (no budget) or a positive number of frames "
                           f"a second, got {fps:g}")
    return fps


def ladder(count: int, has_lod: bool, sh_degree: int, cut_factor: float = 1.0,
           pixels: int | None = None) -> list[Level]:
    """The levels for a scene of ``count`` splats, best first by :func:`predicted_psnr` (with
    the scene's ``cut_factor``).

    Budgets apply only with a level-of-detail tree (``has_lod``) and only below ``count``; the
    SH degree is capped at 0 on levels that also cut splats (view-dependent colour matters
    least in a coarse preview); given the output's ``pixels`` at scale 1, scales that would
    draw fewer than :data:`MIN_DRAFT_PIXELS` are left out."""
    budgets: list[int | None] = [None]
    if has_lod:
        budgets += [b for b in BUDGETS if b < count]
    scales = [s for s in SCALES if s == 1.0 or pixels is None or pixels * s * s >= MIN_DRAFT_PIXELS]
    levels = []
    for b in budgets:
        for s in scales:
            sh = 0 if (b is not None and sh_degree > 0) else None
            levels.append(Level(s, b, sh))
    return sorted(levels, key=lambda lv: (-predicted_psnr(lv, count, cut_factor), -lv.scale))


def _errors(level: Level, count: int) -> tuple[float, float]:
    """The model's squared errors of ``level``'s scale and of its cut (before the overlap)."""
    splats = count if level.budget is None else min(level.budget, count)
    share = max(splats, 1) / max(count, 1)
    return (SCALE_MSE * (1.0 / level.scale - 1.0) ** SCALE_POWER,
            CUT_MSE * (1.0 / share - 1.0) ** CUT_POWER)


def predicted_psnr(level: Level, count: int, cut_factor: float = 1.0) -> float:
    """The PSNR (dB) ``level`` is expected to reach against the exact frame of a scene of
    ``count`` splats (the quality model above, its cut's error times the scene's
    ``cut_factor``; :data:`EXACT_PSNR` for the exact level)."""
    by_scale, by_cut = _errors(level, count)
    by_cut *= cut_factor
    mse = max(by_scale, by_cut) + OVERLAP * min(by_scale, by_cut)
    return EXACT_PSNR if mse <= 10.0 ** (-EXACT_PSNR / 10.0) else -10.0 * math.log10(mse)


def cut_factor_for(level: Level, count: int, measured_psnr: float) -> float | None:
    """The ``cut_factor`` that makes :func:`predicted_psnr` of ``level`` (a cut) equal
    ``measured_psnr``, clamped to CUT_FACTOR_RANGE; None where the level has no cut or the
    measurement says nothing about the cut (its error no larger than the scale's)."""
    by_scale, by_cut = _errors(level, count)
    if level.budget is None or by_cut <= 0.0 or not math.isfinite(measured_psnr):
        return None
    mse = 10.0 ** (-measured_psnr / 10.0)
    cut = mse - OVERLAP * by_scale          # the cut's part, where it dominates
    if cut <= by_scale:
        return None
    lo, hi = CUT_FACTOR_RANGE
    return float(min(hi, max(lo, cut / by_cut)))


#: The exact frame's measured seconds (at rest or moving) are smoothed exponentially, this
#: weight on the newest; where they fit the budget the exact frame is drawn while moving too.
EXACT_SMOOTHING = 0.5


class FrameBudget:
    """Picks a :class:`Level` per moving frame so frames land within ``budget`` seconds.

    ``count``: the scene's splats; ``pixels``: the window's pixels at scale 1; ``has_lod``:
    whether a level-of-detail tree can serve budgets; ``software``: whether the device is a
    software rasteriser (the cost model's prior: :meth:`CostModel.for_device`).  The first frame
    is drawn at the level the prior predicts to fit, not at full detail: nothing was measured
    yet (a 1M-splat scene's first moving frame took 760 ms on llvmpipe).  Call :meth:`level`
    before a frame and :meth:`report` after it with what it drew and how long it took.
    """

    def __init__(self, budget: float, count: int, pixels: int, sh_degree: int = 0,
                 has_lod: bool = False, margin: float = 0.95, hold: float = 1.05, over: float = 1.15,
                 patience: int = 3, probe: float = 0.6, software: bool = True):
        if not (math.isfinite(budget) and budget > 0.0):
            raise SplatglError(f"frame-time budget must be a positive number of seconds, got {budget}")
        self.budget, self.count, self.pixels = float(budget), int(count), int(pixels)
        self.sh_degree = sh_degree
        self.margin, self.hold, self.over, self.patience = margin, hold, over, patience
        self.probe = probe
        self._fast = 0          # frames in a row under ``probe`` times the budget
        self._probe_wait: dict[int, int] = {}   # level index -> frames before probing it again
        self._probing: int | None = None        # the level a probe moved to
        self.model = CostModel.for_device(software)
        self.has_lod, self.cut_factor = has_lod, 1.0
        self.levels = ladder(self.count, has_lod, sh_degree, pixels=self.pixels)
        #: The exact frame's measured seconds, smoothed (:data:`EXACT_SMOOTHING`); None until
        #: one is measured at these pixels.  :meth:`predict` prices the exact level by it.
        self.exact_seconds: float | None = None
        self.index = self.target()   # the level in use (an index into :attr:`levels`): safe
        self._ups = 0           # frames in a row whose target was higher than the level in use
        self._last: tuple[Level, float] | None = None   # the last moving frame's level and seconds

    def set_lod(self, has_lod: bool) -> None:
        """A level-of-detail tree became available (or went away): new ladder, same quality."""
        self.has_lod = has_lod
        self._rebuild()

    def calibrate(self, level: Level, measured_psnr: float) -> bool:
        """``level`` (a cut) measured ``measured_psnr`` against the exact frame of the same
        view: correct the model's cut error for this scene (:func:`cut_factor_for`) and re-rank
        the levels (the one in use keeps its predicted quality).  Returns whether it changed."""
        factor = cut_factor_for(level, self.count, measured_psnr)
        if factor is None or abs(math.log(factor / self.cut_factor)) < 0.05:
            return False
        self.cut_factor = factor
        self._rebuild()
        return True

    def _rebuild(self) -> None:
        level, f = self.current, self.cut_factor
        q = predicted_psnr(level, self.count, f)
        self.levels = ladder(self.count, self.has_lod, self.sh_degree, f, self.pixels)
        self.index = min(range(len(self.levels)),
                         key=lambda i: abs(predicted_psnr(self.levels[i], self.count, f) - q))
        self._probe_wait.clear()

    def observe(self, level: Level, splats: int, seconds: float) -> None:
        """A frame's cost that is not a moving frame (a refinement step): the cost model
        learns from it; the level does not move."""
        self.model.update(float(splats), self.pixels * level.scale * level.scale, float(seconds))
        self._note_exact(level, seconds)

    def _note_exact(self, level: Level, seconds: float) -> None:
        if level.exact and math.isfinite(seconds) and seconds >= 0.0:
            last = self.exact_seconds   # slower: at once (never a slow frame twice); faster: smoothed
            self.exact_seconds = float(seconds) if last is None or seconds > last else \
                EXACT_SMOOTHING * float(seconds) + (1.0 - EXACT_SMOOTHING) * last

    def set_pixels(self, pixels: int) -> None:
        """The window's pixels at scale 1 changed (a resize): the scales it may draw too."""
        if int(pixels) != self.pixels:
            self.exact_seconds = None     # measured at other pixels
            self.pixels = int(pixels)
            self._rebuild()

    def set_budget(self, budget: float) -> None:
        """Seconds a moving frame's draw may take from now on (the viewer's frame period less
        what its window costs besides the draw: :meth:`~.session.Session.note_overhead`)."""
        if not (math.isfinite(budget) and budget > 0.0):
            raise SplatglError(f"frame-time budget must be a positive number of seconds, got {budget}")
        self.budget = float(budget)

    @property
    def current(self) -> Level:
        return self.levels[self.index]

    def predict(self, level: Level) -> float:
        """``level``'s expected seconds: the cost model's, or the exact frame's measured cost
        where there is one and it is lower (a linear model fitted to drafts can price it high)."""
        splats = self.count if level.budget is None else min(level.budget, self.count)
        seconds = self.model.predict(splats, self.pixels * level.scale * level.scale)
        if level.exact and self.exact_seconds is not None:
            return min(seconds, self.exact_seconds)
        return seconds

    def target(self) -> int:
        """The best level whose predicted time fits ``margin * budget`` (the cheapest if none)."""
        limit = self.margin * self.budget
        for i, level in enumerate(self.levels):
            if self.predict(level) <= limit:
                return i
        return len(self.levels) - 1

    def level(self) -> Level:
        """The level of the next moving frame."""
        return self.current

    def resume(self) -> None:
        """Motion starts after a rest: start afresh.  Count the frames that want a better level
        from 0: the count left from before the rest let the level jump up after two frames to
        an over-predicted full-detail level (1.0-1.3 s on 1M splats on an AVX2 llvmpipe).

        Keep the level in use where the last moving frame drew it within ``hold`` budgets: that
        measurement is better evidence than the model, which has learnt the rest's exact frame
        too.  A linear fit to one frame at full detail (donut: 0.3-0.45 s, with the refinement's
        batches) overshot the moving levels' costs, and motion restarted at the ladder's bottom
        (scale 0.1, 12,000 splats, 26 dB) for the three frames patience takes to climb back.
        Otherwise (no moving frame yet, or it was slow) go down to the level the model predicts
        to fit where the one in use is better."""
        last = self._last
        measured = last is not None and last[0] == self.current and last[1] <= self.hold * self.budget
        if self.exact_seconds is not None and self.exact_seconds <= self.margin * self.budget:
            self.index = 0          # the exact frame, measured (at rest) within the budget
        elif not measured:
            self.index = max(self.index, self.target())
        self._ups = 0

    def report(self, level: Level, splats: int, seconds: float) -> None:
        """What the last frame drew (``splats``, at ``level``) and how long it took; moves the
        level for the next frame (see the module doc for the hysteresis)."""
        self.model.update(float(splats), self.pixels * level.scale * level.scale, float(seconds))
        self._note_exact(level, seconds)
        self._last = (level, float(seconds))
        target = self.target()
        probed, self._probing = self._probing, None
        slow = seconds > self.over * self.budget or self.predict(self.current) > self.hold * self.budget
        self._fast = self._fast + 1 if seconds < self.probe * self.budget else 0
        for i in list(self._probe_wait):
            self._probe_wait[i] -= 1
            if self._probe_wait[i] <= 0:
                del self._probe_wait[i]
        if slow:
            if probed is not None:   # a failed probe: not again for a while (longer each time)
                self._backoff = min(getattr(self, "_backoff", PROBE_BACKOFF) * 2, PROBE_BACKOFF_MAX)
                self._probe_wait[probed] = self._backoff
            down = max(target, self.index + (probed is not None))          # down at once
            # ... or, where the level in use is predicted far over the budget, to a better level
            # the model finds cheaper: levels are ranked by quality, not cost, and a
            # level-of-detail tree arriving late (the viewer's) adds cuts that are both.
            # Without this the viewer stayed at the no-tree ladder's bottom (biker: scale 0.1,
            # all splats, 150-250 ms a frame) while 50k-splat cuts fitted.
            current = self.predict(self.current)
            stuck = current > self.over * self.budget and self.predict(self.levels[target]) < current
            self.index, self._ups = (target if stuck else down), 0
        elif target < self.index:
            self._ups += 1
            if self._ups >= self.patience:                      # fast enough for a while: up
                self.index, self._ups = target, 0
        else:
            self._ups = 0
            up = self.index - 1
            if self._fast >= self.patience and up >= 0 and up not in self._probe_wait:
                # Well under budget, yet the model sees nothing better: it may be wrong (it
                # learnt from one level only).  Try one level up; a slow frame comes back.
                self.index, self._probing, self._fast = up, up, 0
