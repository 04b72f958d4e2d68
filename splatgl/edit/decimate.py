"""``--decimate N`` / ``--decimate P%``: merge neighbouring splats until N remain.

The merge is the level-of-detail hierarchy's moment matching
(:func:`splatgl.lod.build.merge_groups`: weights opacity x area, mean, covariance with the
spread of the means, SH and opacity from the children), applied to pairs of neighbours in
rounds instead of to fixed groups:

1. put the splats in Morton order (:func:`~splatgl.scene.spatial.morton_order_clamped_box`)
   and pair consecutive ones (rows 0-1, 2-3, ... in even rounds, 1-2, 3-4, ... in odd ones,
   so pair boundaries move);
2. price each pair: ``w_a w_b / (w_a + w_b) * (|mu_a - mu_b|^2 / (s_a^2 + s_b^2) +
   |c_a - c_b|^2 / 0.1^2)`` with ``w`` = opacity x area, ``s`` the largest scale and ``c`` the
   DC colour (0-1): small, faint, overlapping, similar pairs are cheap; large opaque splats far
   apart or of different colours are dear;
3. while more than 4x the target remain, merge every pair (a uniform halving); from there on
   merge the cheapest pairs, at most half of them per round (so a round removes at most a
   quarter of the splats and the next one re-pairs the merged splats with their new
   neighbours), and never more than the count still to remove; repeat until the target.

Splats that are never merged keep their stored values bit for bit.  3DGS only (a surfel pair's
moments are not a surfel).
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass

import numpy as np

from ..constants import SH_C0
from ..errors import SplatglError
from ..lod.build import area_proxy, merge_groups
from ..scene.splats import Scene, SplatKind, activate_opacities, activate_rotations
from ..scene.spatial import morton_order_clamped_box
from ..splatmath.project import covariance_3d, quat_to_rotmat

#: Pairs per block of the cost and merge computations (float64 temporaries of one block).
BLOCK = 1 << 16
#: The largest share of a round's pairs merged in that round (the adaptive rounds).
ROUND_SHARE = 0.5
#: While more than this many times the target remain, every pair merges (uniform rounds):
#: measured on the shared scenes, choosing cheap pairs pays for the last two halvings, while
#: choosing them through many rounds merges the same regions over and over (docs/editing.md).
UNIFORM_ABOVE = 4
#: Colour difference (0-1 units) that costs as much as centres one combined scale apart.
COLOUR_SCALE = 0.1
#: The largest log-scale merged: the squared scale (a covariance) stays within float64.
MAX_LOG_SCALE = 100


def plural(n: int, word: str) -> str:
    """``"1 splat"``, ``"2 splats"`` (thousands separated)."""
    return f"{n:,} {word}" + ("" if n == 1 else "s")


@dataclass(frozen=True)
class Decimate:
    """Merge neighbours until ``count`` splats remain, or ``percent`` of them (one of the two)."""

    count: int | None = None
    percent: float | None = None
    name = "decimate"

    def __post_init__(self):
        if (self.count is None) == (self.percent is None):
            raise SplatglError("--decimate: give a count N or a percentage P%")
        if self.count is not None and (isinstance(self.count, bool) or int(self.count) != self.count
                                       or self.count < 1):
            raise SplatglError(f"--decimate: the count must be an integer >= 1, got {self.count!r}")
        if self.percent is not None and not (math.isfinite(self.percent)
                                             and 0 < self.percent <= 100):
            raise SplatglError(f"--decimate: the percentage must be in (0, 100], got "
                               f"{self.percent!r}%")

    @classmethod
    def parse(cls, text: str) -> "Decimate":
        """``N`` or ``P%`` (e.g. ``50000``, ``25%``, ``12.5%``)."""
        t = str(text).strip()
        m = re.fullmatch(r"(\d+(?:\.\d*)?|\.\d+)\s*%", t)
        if m:
            return cls(percent=float(m.group(1)))
        if re.fullmatch(r"\d+", t):
            return cls(count=int(t))
        raise SplatglError(f"--decimate: expected a count N or a percentage P%, got {text!r}")

    def target(self, n: int) -> int:
        """The splats left of ``n``: the count (at most ``n``) or the percentage (at least 1)."""
        if self.count is not None:
            return min(int(self.count), n)
        return min(n, max(1, int(round(n * self.percent / 100.0)))) if n else 0

    def describe(self) -> str:
        return (f"to {plural(self.count, 'splat')}" if self.count is not None else
                f"to {self.percent:g}%") + " by moment matching of neighbour pairs"

    def note(self, n: int) -> str:
        """What to say beside the step when ``n`` splats are already at or below the count."""
        if self.count is not None and self.target(n) >= n and n:
            return (f"the scene has {plural(n, 'splat')}, not more than {self.count:,}: "
                    "nothing merged")
        return ""

    def apply(self, scene: Scene, progress=None) -> Scene:
        """``scene`` merged down to :meth:`target` splats (the scene itself when already there)."""
        target = self.target(scene.count)
        if target >= scene.count:
            return scene
        check_kind(scene.kind)
        _check_scales(scene)
        start, rnd = scene.count, 0
        if progress is not None:
            progress(0, start - target, "decimating")  # done == 0 starts the meter's clock
        while scene.count > target:
            share = 1.0 if scene.count > UNIFORM_ABOVE * target else ROUND_SHARE
            with np.errstate(all="ignore"):  # extreme stored values: edit_files checks the result
                scene = _round(scene, scene.count - target, rnd % 2, share)
            rnd += 1
            if progress is not None:
                progress(start - scene.count, start - target, "decimating")
        return scene


def check_kind(kind: SplatKind) -> None:
    """Refuse 2DGS surfels (their merged moments are not a surfel)."""
    if kind is SplatKind.SURFEL_2D:
        raise SplatglError("--decimate: 2DGS surfels cannot be merged (moment matching gives 3D "
                           "Gaussians)")


def _check_scales(scene: Scene) -> None:
    """Refuse splats whose covariance overflows float64 (scale above e^MAX_LOG_SCALE): their
    moments cannot be matched."""
    for start in range(0, scene.count, BLOCK):
        big = np.flatnonzero((scene.log_scales[start:start + BLOCK] > MAX_LOG_SCALE).any(axis=1))
        if big.size:
            raise SplatglError(f"--decimate: splat {start + int(big[0]):,} has a scale above "
                               f"e^{MAX_LOG_SCALE} world units, whose moments overflow: remove "
                               "such splats first (e.g. --remove 'max_scale > 1e40')")


def _round(scene: Scene, need: int, offset: int, share: float) -> Scene:
    """One round: merge the cheapest ``share`` of the Morton-neighbour pairs (at most
    ``need``)."""
    order = morton_order_clamped_box(scene.means.astype(np.float64))
    if scene.count - offset < 2:  # two splats on an odd round: the one pair starts at row 0
        offset = 0
    npairs = (scene.count - offset) // 2
    a = order[offset:offset + 2 * npairs:2]
    b = order[offset + 1:offset + 2 * npairs:2]
    limit = min(need, npairs, max(1, int(npairs * share)))
    cost = np.concatenate([pair_cost(scene, a[s:s + BLOCK], b[s:s + BLOCK])
                           for s in range(0, npairs, BLOCK)])
    chosen = np.sort(np.argpartition(cost, limit - 1)[:limit]) if limit < npairs else np.arange(npairs)
    a, b = a[chosen], b[chosen]
    merged = [merge_pairs(scene, a[s:s + BLOCK], b[s:s + BLOCK]) for s in range(0, limit, BLOCK)]
    keep = np.ones(scene.count, bool)
    keep[a] = keep[b] = False
    return _concat(scene, keep, merged)


def _activated(scene: Scene, rows: np.ndarray):
    """(opacity (P,), scales (P, 3)) float64 of ``rows``, activated now (not cached)."""
    return (activate_opacities(scene.opacity_logits[rows], scene.quats[rows]),
            np.exp(scene.log_scales[rows].astype(np.float64)))


def pair_cost(scene: Scene, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(P,) float64 price of merging rows ``a[i]`` and ``b[i]`` (see the module notes)."""
    oa, sa = _activated(scene, a)
    ob, sb = _activated(scene, b)
    wa, wb = oa * area_proxy(sa), ob * area_proxy(sb)
    d = scene.means[a].astype(np.float64) - scene.means[b].astype(np.float64)
    spread = sa.max(axis=1) ** 2 + sb.max(axis=1) ** 2
    dc = SH_C0 * (scene.sh[a, 0].astype(np.float64) - scene.sh[b, 0].astype(np.float64))
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        mass = np.where(wa + wb > 0, wa * wb / (wa + wb), 0.0)
        cost = mass * ((d * d).sum(axis=1) / np.maximum(spread, 1e-300)
                       + (dc * dc).sum(axis=1) / COLOUR_SCALE ** 2)
    return np.where(np.isfinite(cost), cost, np.inf)


def merge_pairs(scene: Scene, a: np.ndarray, b: np.ndarray) -> Scene:
    """The moment-matched parents of rows ``a[i]`` and ``b[i]`` ((P,) each), as a Scene."""
    rows = np.stack([a, b], 1).ravel()  # a0 b0 a1 b1 ...: groups of two consecutive rows
    opac, scales = _activated(scene, rows)
    rot = quat_to_rotmat(activate_rotations(scene.quats[rows]))
    mu, _, p_opac, _, p_sh, p_scales, p_quat, _ = merge_groups(
        scene.means[rows].astype(np.float64), covariance_3d(rot, scales), opac, area_proxy(scales),
        scene.sh[rows].astype(np.float64), 2)
    return Scene.from_activated(mu, p_quat, p_scales, p_opac, p_sh)


def _concat(scene: Scene, keep: np.ndarray, merged: list[Scene]) -> Scene:
    """The kept rows of ``scene`` followed by the ``merged`` parents, as one Scene."""
    names = ("means", "quats", "log_scales", "opacity_logits", "sh")
    arrays = []
    for name in names:
        parts = [getattr(scene, name)[keep]] + [getattr(m, name) for m in merged]
        out = np.concatenate(parts)
        out.flags.writeable = False
        arrays.append(out)
    return Scene(*arrays, scene.kind)
