"""``splatgl info [--stats]`` of a binary PLY larger than ``--memory`` (issue 41 item 5): the
same report, from the file read a block of rows at a time (:mod:`.streamed`), in two passes
(three with ``--stats``: the overdraw needs the default view, which needs the 1-99 % box).

Exact: the count, min, max, the number of values that are not finite, the share of opacities
below 1/255, the 1-99 % box of the centres (:class:`splatgl.lod.ply_rows.BoxFinder`) and so the
overdraw, and every percentile of float32 values (opacity, scale): each order statistic is
found by a histogram of the upper 16 bits of the values' order-preserving keys (first pass),
then of the next 16 within the bins that hold them (second), and interpolated as
:func:`numpy.percentile` does.  The mean is a sum of block sums (a few ulps from NumPy's
pairwise sum).  Percentiles of float64 values (the ``--stats`` attributes, anisotropy) are
approximate: the two passes find the upper 32 bits of the 64-bit key, so each order statistic
is within a relative 2^-20 (about 1e-6) of the exact one (of its absolute size near zero, where
float64 is denser), far below the 4 digits shown.
"""

from __future__ import annotations

import numpy as np

from ..constants import ALPHA_MIN
from ..formats import scene_source
from ..lod.ply_rows import BoxFinder, float_keys, key_floats
from ..scene.settings import RenderSettings, resolve_near
from .attributes import ATTRIBUTES, Rows, names_for
from .statistics import PERCENTILES, overdraw, _fragments
from .streamed import IN_MEMORY_COPIES, block_rows, memory_bound, sources_of

_SIGN = np.uint64(1 << 63)
#: Histograms a summary of three percentiles holds at most: the upper bits' and six others.
HISTOGRAMS = 7


class Quantiles:
    """min, max, mean, nonfinite and ``percentiles`` of values seen block by block, twice:
    :meth:`first` every block, then :meth:`second` every block (see the module notes)."""

    def __init__(self, percentiles, float32: bool):
        self.percentiles, self.float32 = tuple(percentiles), float32
        self.high = np.zeros(1 << 16, np.int64)
        self.n = self.nonfinite = 0
        self.lo, self.hi, self.sum = np.inf, -np.inf, 0.0
        self.bins = None

    def _keys(self, finite: np.ndarray) -> np.ndarray:
        if self.float32:
            return float_keys(finite)
        u = np.ascontiguousarray(finite, np.float64).view(np.uint64)
        return (np.where(u & _SIGN, ~u, u | _SIGN) >> np.uint64(32)).astype(np.uint32)

    def _value(self, key: int) -> float:
        if self.float32:
            return float(key_floats(np.uint32(key)))
        k = np.uint64((key << 32) | (1 << 31))  # the middle of the bin
        u = k & ~_SIGN if k & _SIGN else ~k
        return float(min(max(np.array(u, np.uint64).view(np.float64), self.lo), self.hi))

    def first(self, values: np.ndarray) -> None:
        values = np.asarray(values).ravel()
        finite = values[np.isfinite(values)]
        self.nonfinite += values.size - finite.size
        if finite.size:
            self.n += finite.size
            self.lo, self.hi = min(self.lo, finite.min()), max(self.hi, finite.max())
            self.sum += float(finite.sum(dtype=np.float64))
            self.high += np.bincount(self._keys(finite) >> np.uint32(16), minlength=1 << 16)

    def _plan(self) -> None:
        before = np.concatenate([[0], np.cumsum(self.high)])
        self.ranks, self.bins = [], {}
        for p in self.percentiles:
            virtual = (self.n - 1) * np.true_divide(p, 100)  # numpy's 'linear'
            lo = int(np.clip(np.floor(virtual), 0, self.n - 1))
            hi = int(np.clip(lo + 1, 0, self.n - 1))
            self.ranks.append((lo, hi, virtual - np.floor(virtual)))
            for rank in (lo, hi):
                b = int(np.searchsorted(before, rank, side="right") - 1)
                self.bins[b] = (int(before[b]), np.zeros(1 << 16, np.int64))

    def second(self, values: np.ndarray) -> None:
        if self.n == 0:
            return
        if self.bins is None:
            self._plan()
        values = np.asarray(values).ravel()
        keys = self._keys(values[np.isfinite(values)])
        upper = keys >> np.uint32(16)
        for b, (_, hist) in self.bins.items():
            sel = keys[upper == b]
            if sel.size:
                hist += np.bincount(sel & np.uint32(0xFFFF), minlength=1 << 16)

    def _rank(self, rank: int) -> float:
        for b, (before, hist) in self.bins.items():
            cum = before + np.cumsum(hist)
            if before <= rank < cum[-1]:
                return self._value((b << 16) | int(np.searchsorted(cum, rank, side="right")))
        raise AssertionError("rank outside the histogram")

    def result(self) -> dict:
        """``min``, ``max``, ``mean``, ``nonfinite`` and one value per percentile (by its
        number); only ``nonfinite`` where no value is finite."""
        if self.n == 0:
            return {"nonfinite": self.nonfinite}
        if self.bins is None:
            self._plan()
        out = {"min": float(self.lo), "max": float(self.hi), "mean": self.sum / self.n,
               "nonfinite": self.nonfinite}
        for p, (lo, hi, gamma) in zip(self.percentiles, self.ranks):
            a, b = self._rank(lo), self._rank(hi)
            value = a + (b - a) * gamma if gamma < 0.5 else b - (b - a) * (1 - gamma)
            out[p] = float(value)
        return out


def info_streamed(path, memory: int | None, drop_invalid: bool = False, stats: bool = False):
    """``(scene_info, attribute statistics or None, overdraw or None)`` of the binary PLY
    ``path`` read a block at a time, where ``memory`` (bytes; None: the default, half this
    machine's RAM) is below what loading it takes;
    None to load it whole (another format, or it fits)."""
    memory = memory_bound(memory)
    sources = sources_of([path], drop_invalid)
    if sources is None or IN_MEMORY_COPIES * sources[0].in_memory_bytes() <= memory:
        return None
    src = sources[0]
    # the histograms first: per summary one of the upper bits and at most one per order
    # statistic wanted (6 for three percentiles) of the lower, 2^16 int64 counts each
    summaries = 3 + (sum(1 for a in ATTRIBUTES.values() if a.statistic) if stats else 0)
    rows = block_rows(memory, src.dtype.itemsize, src.values,
                      fixed=summaries * HISTOGRAMS * (8 << 16))
    box = BoxFinder(src.count)
    parts = {"opacity": Quantiles([50.0], True), "scale": Quantiles([50.0], True),
             "anisotropy": Quantiles([50.0], False)}
    low, mins, maxs, attrs, count = 0, [], [], None, 0
    for second in (False, True):
        for first, block in src.blocks(rows, warn=not second):
            opac, scales = block.opacities, block.scales
            with np.errstate(divide="ignore", invalid="ignore"):
                ratio = scales.max(axis=1).astype(np.float64) / scales.min(axis=1)
            own = {"opacity": opac, "scale": scales, "anisotropy": ratio}
            if attrs is None:
                attrs = {n: Quantiles((PERCENTILES[0], 50.0, PERCENTILES[1]), False)
                         for n in names_for(block) if ATTRIBUTES[n].statistic} if stats else {}
            values = {}
            if stats:
                r = Rows(block, 0, block.count, first)
                with np.errstate(all="ignore"):  # beyond float64: not finite
                    values = {n: ATTRIBUTES[n].compute(r) for n in attrs}
            if second:
                box.add_second(block.means)
            else:
                box.add_first(block.means)
                count += block.count
                low += int(np.count_nonzero(opac.astype(np.float64) < ALPHA_MIN))
                mins.append(block.means.min(axis=0))
                maxs.append(block.means.max(axis=0))
            for found, table in ((own, parts), (values, attrs)):
                for name, q in table.items():
                    (q.second if second else q.first)(found[name])
            kind, degree, stand_in = block.kind, block.sh_degree, block
    lo, hi = box.box() if count == src.count else _box_of_kept(src, rows, count)
    # np.percentile of float32 means interpolates in float64 and returns float32
    lo, hi = (np.asarray(v, np.float32).astype(np.float64) for v in (lo, hi))
    p = {k: q.result() for k, q in parts.items()}
    info = {"count": count, "kind": kind.value, "sh_degree": degree,
            "bounds": {"min": [float(v) for v in np.min(mins, axis=0)],
                       "max": [float(v) for v in np.max(maxs, axis=0)]},
            "robust_bounds": {"min": [float(v) for v in lo], "max": [float(v) for v in hi]},
            "opacity": {"min": p["opacity"]["min"], "median": p["opacity"][50.0],
                        "max": p["opacity"]["max"], "below_min_alpha": low / count},
            "scale": {"min": p["scale"]["min"], "median": p["scale"][50.0],
                      "max": p["scale"]["max"]},
            "anisotropy": {"median": p["anisotropy"][50.0], "max": p["anisotropy"]["max"]}}
    if not stats:
        return info, None, None
    table = {}
    for name, q in attrs.items():
        r = q.result()
        entry = {"unit": ATTRIBUTES[name].unit, "nonfinite": r["nonfinite"]}
        if "min" in r:
            entry.update(min=r["min"], p1=r[PERCENTILES[0]], median=r[50.0],
                         p99=r[PERCENTILES[1]], max=r["max"], mean=r["mean"])
        table[name] = entry
    return info, table, _overdraw(src, rows, stand_in, path, (lo, hi))


def _box_of_kept(src, rows, count):
    """The box when ``--drop-invalid`` dropped rows (the finder counts the file's rows)."""
    box = BoxFinder(count)
    for second in (False, True):
        for _, block in src.blocks(rows, warn=False):
            (box.add_second if second else box.add_first)(block.means)
    return box.box()


def _overdraw(src, rows, stand_in, path, bounds) -> dict:
    """:func:`splatgl.edit.statistics.overdraw` summed block by block (a third pass)."""
    frame = stand_in.subset(slice(0, 1))  # frames as the whole scene: its box, its file
    object.__setattr__(frame, "source", scene_source(path))
    frame.__dict__["robust_bounds"] = bounds
    draw = overdraw(frame)
    if "not_estimated" in draw:
        return draw
    from ..cameras.framing import default_camera

    cam = default_camera(frame)
    near = resolve_near(RenderSettings(), frame.robust_radius)
    total = 0.0
    with np.errstate(all="ignore"):
        for _, block in src.blocks(rows, warn=False):
            total += _fragments(block, cam, near)
    pixels = cam.width * cam.height
    return {"fragments": total, "pixels": pixels, "per_pixel": total / pixels,
            "width": cam.width, "height": cam.height}
