"""Explain how an image differs from the reference: which of the approximations real viewers make
(the reference's emulation knobs, :mod:`splatgl.scene.emulation`, and a few whole rules) bring the
reference closest to it, alone and combined, and how many dB each accounts for.

Method.  The reference is rendered once as it is and once per candidate (one knob changed); a
candidate "explains" part of the difference when it raises the PSNR against the image by more
than MIN_GAIN_DB.  Then a greedy combination: starting from the plain reference, add the
candidate (of those that helped alone, at most one value per knob) that raises the PSNR most
together with those already chosen, until none adds MIN_GAIN_DB or MAX_STEPS are taken.  Each
step's gain is the dB that knob accounts for, given the ones before it; what is left is the
image's own difference.

Candidates (:func:`candidates`): ``sort=bucket16``; each other ``extent``; ``min_alpha=0.01``;
``low_pass=0.1`` (Mip-Splatting); the antialiasing compensation switched; each SH cap below the
scene's degree; ``half=on``; the other alpha clamp (0.999 or 0.99); the other sort depth (distance
or z); the per-pixel order (perspective and orthographic cameras); gsplat's rules
(``convention=gsplat``: per-axis opacity-aware extent, clamp 0.999, inclusive stop).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Callable

import numpy as np

from ...cameras.camera import Camera
from ...cameras.orthographic import Orthographic
from ...cameras.pinhole import Pinhole
from ...constants import ALPHA_MAX, GSPLAT_ALPHA_MAX
from ...scene.emulation import EXTENTS
from ...scene.splats import Scene
from ...scene.settings import Convention, Order, RenderSettings
from .metrics import psnr

#: A candidate must raise the PSNR by more than this to count (dB).
MIN_GAIN_DB = 0.05
#: At most this many knobs are combined.
MAX_STEPS = 4


@dataclass(frozen=True)
class Candidate:
    """One change to the reference: ``label`` (``KNOB=VALUE``, as ``--emulate`` spells it),
    ``knob`` (the name; one value per knob in a combination) and how it changes settings."""

    label: str
    knob: str
    apply: Callable[[RenderSettings], RenderSettings]


def _knob(text: str) -> Candidate:
    name = text.split("=", 1)[0]
    return Candidate(text, name, lambda s: dataclasses.replace(s, emulation=s.emulation.with_knob(text)))


def candidates(scene: Scene, camera: Camera, settings: RenderSettings) -> list[Candidate]:
    """The changes :func:`explain` tries for this scene, camera and settings (module doc)."""
    em = settings.emulation
    out = []
    if em.sort != "bucket16":
        out.append(_knob("sort=bucket16"))
    out += [_knob(f"extent={e}") for e in EXTENTS if e != em.extent]
    if em.min_alpha != 0.01:
        out.append(_knob("min_alpha=0.01"))
    if em.low_pass != 0.1:
        out.append(_knob("low_pass=0.1"))
    comp = settings.antialias if em.compensation is None else em.compensation
    out.append(_knob(f"compensation={'off' if comp else 'on'}"))
    degree = scene.sh_degree if settings.sh_degree is None else min(scene.sh_degree, settings.sh_degree)
    if em.sh is not None:
        degree = min(degree, em.sh)
    out += [_knob(f"sh={d}") for d in range(degree)]
    if not em.half:
        out.append(_knob("half=on"))
    gsplat = settings.convention is Convention.GSPLAT
    clamp = em.alpha_max if em.alpha_max is not None else (GSPLAT_ALPHA_MAX if gsplat else ALPHA_MAX)
    out.append(_knob(f"alpha_max={ALPHA_MAX if clamp != ALPHA_MAX else GSPLAT_ALPHA_MAX:g}"))
    lens = not isinstance(camera.model, (Pinhole, Orthographic))
    by = em.depth if em.depth != "auto" else ("distance" if lens else "z")
    out.append(_knob(f"depth={'z' if by == 'distance' else 'distance'}"))
    if settings.order is Order.GLOBAL and not lens:
        out.append(Candidate("order=per-pixel", "order",
                             lambda s: dataclasses.replace(s, order=Order.PER_PIXEL)))
    if not gsplat:
        out.append(Candidate("convention=gsplat", "convention",
                             lambda s: dataclasses.replace(s, convention=Convention.GSPLAT)))
    return out


@dataclass(frozen=True)
class Explanation:
    """What :func:`explain` found.

    base_psnr: the plain reference against the image (dB).  singles: (label, PSNR) of every
    candidate alone, best first.  steps: (label, PSNR after adding it) of the greedy
    combination, in order.  settings: the reference's settings of the combination.
    """

    base_psnr: float
    singles: tuple[tuple[str, float], ...]
    steps: tuple[tuple[str, float], ...]
    settings: RenderSettings

    @property
    def best(self) -> str | None:
        """The single candidate that explains most (None: none gains MIN_GAIN_DB)."""
        if self.singles and self.singles[0][1] > self.base_psnr + MIN_GAIN_DB:
            return self.singles[0][0]
        return None

    @property
    def final_psnr(self) -> float:
        return self.steps[-1][1] if self.steps else self.base_psnr

    def gains(self) -> list[tuple[str, float]]:
        """(label, dB it accounts for) of each combination step."""
        prev, out = self.base_psnr, []
        for label, value in self.steps:
            out.append((label, value - prev))
            prev = value
        return out

    def as_dict(self) -> dict:
        fin = lambda v: None if v == float("inf") else v  # noqa: E731
        return {"base_psnr": fin(self.base_psnr), "best": self.best,
                "singles": [{"knob": k, "psnr": fin(v), "gain_db": fin(v - self.base_psnr)}
                            for k, v in self.singles],
                "combination": [{"knob": k, "psnr": fin(v), "gain_db": fin(g)}
                                for (k, v), (_, g) in zip(self.steps, self.gains())],
                "final_psnr": fin(self.final_psnr)}

    def lines(self) -> list[str]:
        """The report ``compare --explain`` prints."""
        out = [f"  explain: the reference against the image {_db(self.base_psnr)}; each knob alone:"]
        for label, value in self.singles:
            out.append(f"    {label:<22} {_db(value):>9}  {value - self.base_psnr:+7.2f} dB")
        if not self.steps:
            out.append("  no knob brings the reference closer: the difference is the image's own")
            return out
        out.append("  combined (greedy), the dB each accounts for:")
        for (label, value), (_, gain) in zip(self.steps, self.gains()):
            out.append(f"    + {label:<20} {_db(value):>9}  {gain:+7.2f} dB")
        labels = " ".join(label for label, _ in self.steps)
        out.append(f"  best explanation: {labels} ({_db(self.base_psnr)} -> {_db(self.final_psnr)}; "
                   f"reproduce: {reproduce(label for label, _ in self.steps)})")
        return out


def reproduce(labels) -> str:
    """The options that put the reference in the state of these labels: ``--emulate K=V`` for
    knobs, ``--order per-pixel`` and ``--convention gsplat`` for the whole rules."""
    parts = []
    for label in labels:
        name, value = label.split("=", 1)
        parts.append(f"--{name} {value}" if name in ("order", "convention") else f"--emulate {label}")
    return " ".join(parts)


def _db(value: float) -> str:
    return "inf dB" if value == float("inf") else f"{value:.2f} dB"


def explain(render: Callable[[RenderSettings], np.ndarray], target: np.ndarray,
            settings: RenderSettings, options: list[Candidate], progress=None) -> Explanation:
    """Rank ``options`` by how close each brings ``render(settings')`` to ``target`` (module doc).

    ``render``: settings -> (H, W, 3) composited reference RGB; ``target``: the image, (H, W, 3).
    ``progress``: optional ``progress(done, total, what)``.
    """
    cache: dict[tuple, float] = {}

    def score(chosen: tuple[Candidate, ...]) -> float:
        key = tuple(c.label for c in chosen)
        if key not in cache:
            s = settings
            for c in chosen:
                s = c.apply(s)
            cache[key] = psnr(render(s), target)
            if progress is not None:
                progress(len(cache), len(options) + 1, "explain: rendering the reference with each knob")
        return cache[key]

    base = score(())
    singles = sorted(((c, score((c,))) for c in options), key=lambda e: -e[1])
    helpful = [c for c, v in singles if v > base + MIN_GAIN_DB]
    chosen: tuple[Candidate, ...] = ()
    steps, current = [], base
    while helpful and len(chosen) < MAX_STEPS:
        trial = [(c, score(chosen + (c,))) for c in helpful if c.knob not in {x.knob for x in chosen}]
        if not trial:
            break
        best, value = max(trial, key=lambda e: e[1])
        if value <= current + MIN_GAIN_DB:
            break
        chosen += (best,)
        steps.append((best.label, value))
        current = value
    final = settings
    for c in chosen:
        final = c.apply(final)
    return Explanation(base, tuple((c.label, v) for c, v in singles), tuple(steps), final)
