"""Benchmark output: a terminal table, CSV, JSON, and frame time against error as a plot."""

from __future__ import annotations

import csv
import json
import math
from pathlib import Path

from .runner import BenchRow


def _fmt(value, spec: str, missing: str = "-") -> str:
    if value is None:
        return missing
    if isinstance(value, float) and math.isinf(value):
        return "inf"
    return format(value, spec)


def table(rows: list[BenchRow]) -> str:
    """A fixed-width table, one block per scene."""
    head = (f"{'config':<32} {'ms':>8} {'p10-p90':>15} {'cull+sort':>9} {'xlimit':>7} {'drawn':>8} "
            f"{'frag eff':>8} {'PSNR':>7} {'max err':>8} {'>1/255':>8}")
    out = []
    for scene in dict.fromkeys(r.scene for r in rows):
        sub = [r for r in rows if r.scene == scene]
        out.append(f"\n{scene} ({sub[0].splats} splats)")
        out.append(head)
        for r in sub:
            spread = f"{r.frame_ms_p10:.1f}-{r.frame_ms_p90:.1f}"
            cs = (r.stages_ms["cull"] + r.stages_ms["sort"]) if "cull" in r.stages_ms else None
            out.append(
                f"{r.config:<32} {r.frame_ms:>8.1f} {spread:>15} {_fmt(cs, '.1f'):>9} "
                f"{_fmt(r.limit_ratio, '.2f'):>7} "
                f"{_fmt(r.drawn, 'd'):>8} {_fmt(r.fragment_efficiency, '.3f'):>8} "
                f"{_fmt(r.psnr, '.1f'):>7} {_fmt(r.max_abs, '.4f'):>8} "
                f"{'-' if r.off_1 is None else format(r.off_1 * 100, '.3f') + '%':>8}")
    return "\n".join(out)


def write_csv(path: Path, rows: list[BenchRow]) -> None:
    stage_names = sorted({k for r in rows for k in r.stages_ms})
    fields = [k for k in rows[0].as_dict() if k != "stages_ms"] + [f"{s}_ms" for s in stage_names]
    with open(path, "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=fields)
        w.writeheader()
        for r in rows:
            d = r.as_dict()
            stages = d.pop("stages_ms")
            d.update({f"{s}_ms": stages.get(s) for s in stage_names})
            w.writerow(d)


def write_json(path: Path, rows: list[BenchRow], extra: dict) -> None:
    path.write_text(json.dumps({**extra, "rows": [r.as_dict() for r in rows]}, indent=1) + "\n")


def pareto_front(points: list[tuple[float, float]]) -> list[int]:
    """Indices of points (time, error) that no other point beats in both (lower is better)."""
    front = []
    for i, (t, e) in enumerate(points):
        if not any((t2 <= t and e2 <= e) and (t2 < t or e2 < e) for j, (t2, e2) in enumerate(points) if j != i):
            front.append(i)
    return sorted(front, key=lambda i: points[i][0])


def plot(path: Path, rows: list[BenchRow]) -> None:
    """Frame time against RMS error (from PSNR), one panel per scene, Pareto front marked."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import matplotlib.ticker

    scenes = list(dict.fromkeys(r.scene for r in rows))
    cols = min(2, len(scenes))
    nrows = (len(scenes) + cols - 1) // cols
    fig, axes = plt.subplots(nrows, cols, figsize=(7.0 * cols, 5.4 * nrows), squeeze=False)
    for ax in axes.ravel()[len(scenes):]:
        ax.set_visible(False)
    for ax, scene in zip(axes.ravel(), scenes):
        sub = [r for r in rows if r.scene == scene and r.psnr is not None]
        floor = 1e-7  # identical images (the reference itself) sit on the floor
        pts = [(r.frame_ms, max(floor, 10 ** (-r.psnr / 20) if not math.isinf(r.psnr) else floor)) for r in sub]
        front = pareto_front(pts)
        ax.scatter([p[0] for p in pts], [p[1] for p in pts], c="tab:blue", s=22, zorder=3)
        ax.plot([pts[i][0] for i in front], [pts[i][1] for i in front], "-o", c="tab:red", ms=7,
                mfc="none", zorder=2, label="Pareto front")
        for r, (x, y) in zip(sub, pts):
            ax.annotate(r.config, (x, y), fontsize=7, xytext=(3, 3), textcoords="offset points")
        limit = next((r.frame_ms for r in rows if r.scene == scene and r.group == "limit"), None)
        if limit:
            ax.axvline(limit, ls="--", c="gray", lw=1, label=f"limit row {limit:.0f} ms")
        log_axes(ax, "median frame time (ms)", "RMS error against the reference",
                 f"{scene} ({sub[0].splats if sub else 0} splats)", legend_size=8)
        ax.xaxis.set_major_formatter(matplotlib.ticker.ScalarFormatter())
        ax.xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
    fig.tight_layout()
    save_figure(fig, path)


def log_axes(ax, xlabel: str, ylabel: str, title: str, legend_size: int) -> None:
    """A frame-time-against-error panel's axes: both logarithmic, labelled, titled, a light grid
    and the legend."""
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.set_title(title)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=legend_size)


def save_figure(fig, path: Path) -> None:
    """Write a matplotlib figure atomically (:func:`splatgl.writing.atomic.atomic_target`) and
    close it; every benchmark plot goes through here."""
    import matplotlib.pyplot as plt

    from ...writing.atomic import atomic_target

    try:
        with atomic_target(path) as tmp:
            fig.savefig(tmp, dpi=110)
    finally:
        plt.close(fig)
