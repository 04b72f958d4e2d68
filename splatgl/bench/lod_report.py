"""Level-of-detail benchmark output: the per-(path, configuration) summary of the frames
:func:`splatgl.bench.lod_bench.bench_lod` measured, its table and the Pareto plot (frame time
against RMS error)."""

from __future__ import annotations

import math
import statistics
from pathlib import Path
from typing import TYPE_CHECKING

from .report import save_figure

if TYPE_CHECKING:
    from .lod_bench import LodFrame

#: Frames with at least this distance multiple count as far views.
FAR_FROM = 3.0


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


def table(summ: list[dict]) -> str:
    f = lambda v, s: "-" if v is None else ("inf" if isinstance(v, float) and math.isinf(v) else format(v, s))
    out = [f"{'scene':>5} {'path':>10} {'config':>16} {'ms':>8} {'full ms':>8} {'far x':>6} "
           f"{'max LOD/full':>12} {'min PSNR':>8} {'min SSIM':>8} {'pop PSNR':>8} {'pop max':>7} "
           f"{'pop mean':>8} {'cut max':>7} {'cut mean':>8} {'F max':>6} {'F mean':>7} "
           f"{'cut nodes':>10} {'cut ms':>7}"]
    for s in summ:
        out.append(f"{s['scene']:>5} {s['path']:>10} {s['config']:>16} {s['frame_ms']:>8.0f} "
                   f"{s['full_ms']:>8.0f} {f(s['far_speedup'], '.2f'):>6} {s['slowest_ratio']:>12.2f} "
                   f"{f(s['min_psnr'], '.1f'):>8} {s['min_ssim']:>8.4f} "
                   f"{f(s['min_popping_psnr'], '.1f'):>8} {f(s['pop_max'], '.3f'):>7} "
                   f"{f(s['pop_mean'], '.5f'):>8} {f(s['cut_change_max'], '.3f'):>7} "
                   f"{f(s['cut_change_mean'], '.5f'):>8} {f(s['full_change_max'], '.3f'):>6} "
                   f"{f(s['full_change_mean'], '.4f'):>7} {s['cut_nodes']:>10,.0f} {s['cut_ms']:>7.0f}")
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
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("frame time (ms)")
        ax.set_ylabel("RMS error against full detail")
        ax.set_title(f"{scene} splats, {p}")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=7)
    fig.tight_layout()
    save_figure(fig, path)
