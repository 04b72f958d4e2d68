"""Level-of-detail benchmark output: the per-(path, configuration) summary of the frames
:func:`splatgl.measure.bench.lod_bench.bench_lod` measured, its table and the Pareto plot (frame time
against RMS error)."""

from __future__ import annotations

import statistics
from dataclasses import dataclass
from pathlib import Path

from .report import _fmt, log_axes, save_figure

#: Frames with at least this distance multiple count as far views.
FAR_FROM = 3.0


@dataclass(frozen=True)
class LodFrame:
    """One frame :func:`splatgl.measure.bench.lod_bench.bench_lod` measured (the popping figures
    are defined in its module doc)."""

    scene: str
    path: str
    config: str
    frame: int
    distance: float
    frame_ms: float
    full_ms: float
    drawn: int
    cut_nodes: int
    cut_ms: float
    psnr: float | None
    ssim: float
    popping_psnr: float | None
    pop_max: float | None = None  # max |D| over pixels and RGB (see the module docstring)
    pop_mean: float | None = None  # mean |D|
    cut_change_max: float | None = None  # max |L[k] - L'[k]|, L' drawn with frame k-1's cut
    cut_change_mean: float | None = None  # mean |L[k] - L'[k]|
    full_change_max: float | None = None  # max |F[k+1] - F[k]|
    full_change_mean: float | None = None  # mean |F[k+1] - F[k]|
    leaves: bool = False  # the frame drew the leaves (no cut)


def summary(rows: list[LodFrame]) -> list[dict]:
    """Per (scene, path, config): median frame ms, median full ms, far-view speed-up (median
    of full / LOD over frames at >= FAR_FROM x), the slowest frame's LOD / full ratio, worst
    PSNR and SSIM, worst popping PSNR, the largest and the mean per-pixel change between
    consecutive frames that the LOD adds (and full detail's own), median cut nodes and cut ms."""
    out = []
    keys = dict.fromkeys((r.scene, r.path, r.config) for r in rows)
    for scene, path, config in keys:
        sub = [r for r in rows if (r.scene, r.path, r.config) == (scene, path, config)]
        far = [r.full_ms / r.frame_ms for r in sub if r.distance >= FAR_FROM]
        psnrs = [r.psnr if r.psnr is not None else float("inf") for r in sub]
        pops = [r.popping_psnr for r in sub if r.popping_psnr is not None]
        steps = [r for r in sub if r.pop_max is not None]
        cuts = [r for r in sub if r.cut_change_max is not None]
        out.append({
            "scene": scene, "path": path, "config": config,
            "frame_ms": statistics.median(r.frame_ms for r in sub),
            "full_ms": statistics.median(r.full_ms for r in sub),
            "far_speedup": statistics.median(far) if far else None,
            "slowest_ratio": max(r.frame_ms / r.full_ms for r in sub),
            "min_psnr": min(psnrs), "min_ssim": min(r.ssim for r in sub),
            "min_popping_psnr": min(pops) if pops else None,
            "pop_max": max((r.pop_max for r in steps), default=None),
            "pop_mean": statistics.mean(r.pop_mean for r in steps) if steps else None,
            "cut_change_max": max((r.cut_change_max for r in cuts), default=None),
            "cut_change_mean": statistics.mean(r.cut_change_mean for r in cuts) if cuts else None,
            "full_change_max": max((r.full_change_max for r in steps), default=None),
            "full_change_mean": statistics.mean(r.full_change_mean for r in steps) if steps else None,
            "cut_nodes": statistics.median(r.cut_nodes for r in sub),
            "cut_ms": statistics.median(r.cut_ms for r in sub),
        })
    return out


#: The table's columns: title, key of :func:`summary`'s rows, width, number format.
COLUMNS = (("scene", "scene", 5, ""), ("path", "path", 10, ""), ("config", "config", 16, ""),
           ("ms", "frame_ms", 8, ".0f"), ("full ms", "full_ms", 8, ".0f"), ("far x", "far_speedup", 6, ".2f"),
           ("max LOD/full", "slowest_ratio", 12, ".2f"), ("min PSNR", "min_psnr", 8, ".1f"),
           ("min SSIM", "min_ssim", 8, ".4f"), ("pop PSNR", "min_popping_psnr", 8, ".1f"),
           ("pop max", "pop_max", 7, ".3f"), ("pop mean", "pop_mean", 8, ".5f"),
           ("cut max", "cut_change_max", 7, ".3f"), ("cut mean", "cut_change_mean", 8, ".5f"),
           ("F max", "full_change_max", 6, ".3f"), ("F mean", "full_change_mean", 7, ".4f"),
           ("cut nodes", "cut_nodes", 10, ",.0f"), ("cut ms", "cut_ms", 7, ".0f"))


def table(summ: list[dict]) -> str:
    """One right-aligned line per summary row ("-" where a figure is missing)."""
    out = [" ".join(f"{title:>{width}}" for title, _, width, _ in COLUMNS)]
    out += [" ".join(f"{_fmt(s[key], spec):>{width}}" for _, key, width, spec in COLUMNS) for s in summ]
    return "\n".join(out)


def plot(path: Path, rows: list[LodFrame]) -> None:
    """Frame time against RMS error (per frame), one panel per (scene, path), full detail as a
    vertical line per frame's median."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    panels = list(dict.fromkeys((r.scene, r.path) for r in rows))
    fig, axes = plt.subplots(1, len(panels), figsize=(6.5 * len(panels), 5), squeeze=False)
    for ax, (scene, p) in zip(axes[0], panels):
        sub = [r for r in rows if (r.scene, r.path) == (scene, p)]
        for config in dict.fromkeys(r.config for r in sub):
            pts = [(r.frame_ms, 10 ** (-(r.psnr if r.psnr is not None else 140) / 20))
                   for r in sub if r.config == config]
            ax.scatter(*zip(*pts), s=16, label=config)
        ax.axvline(statistics.median(r.full_ms for r in sub), ls="--", c="gray",
                   label="full detail (median)")
        ax.axhline(10 ** (-40 / 20), ls=":", c="red", lw=1, label="40 dB")
        log_axes(ax, "frame time (ms)", "RMS error against full detail", f"{scene} splats, {p}", legend_size=7)
    fig.tight_layout()
    save_figure(fig, path)
