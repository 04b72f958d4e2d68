"""``bench --scale --lod``'s outputs: scale-lod.json, the table printed and scale-lod.png (memory
and time against size, log axes)."""

from __future__ import annotations

import json
from pathlib import Path

from ...writing.atomic import atomic_write_text
from .report import save_figure
from .scale_report import loglog_slope

#: (label, step, field) of the memory series: each step's peak resident memory.
MEMORY = (("scene file", "scene"), ("LOD build", "build"), ("open", "open"),
          ("first frame", "frame"), ("far view frame", "far"), ("flight", "flight"),
          ("full detail", "full"))
#: (label, step, field, scale) of the time series (seconds).
TIMES = (("scene file (s)", "scene", "seconds", 1.0), ("LOD build (s)", "build", "seconds", 1.0),
         ("open (s)", "open", "seconds", 1.0), ("first frame, cold (s)", "frame", "wall_s", 1.0),
         ("far view frame, cold (s)", "far", "wall_s", 1.0),
         ("moving frame (s)", "flight", "frame_ms_median", 1e-3),
         ("rest to exact (s)", "flight", "rest_to_exact_s", 1.0))


def value(row: dict, step: str, field: str):
    v = row.get(step, {}).get(field)
    return v if isinstance(v, (int, float)) else None


def write_json(path: Path, report: dict) -> None:
    slopes = {label: loglog_slope([r["splats"] for r in report["rows"]],
                                  [value(r, step, "peak_rss_mb") for r in report["rows"]])
              for label, step in MEMORY}
    atomic_write_text(path, json.dumps({**report, "memory_slopes": slopes}, indent=1) + "\n")


def _f(v, fmt: str) -> str:
    return "-" if v is None else format(v, fmt)


def table(rows: list[dict]) -> str:
    """One line a size: build s / MB, open s / MB, first and far frames s / MB, fps, rest to
    exact, PSNRs."""
    head = ("| splats | build s | build MB | open s | open MB | first frame s (cold) | first frame MB "
            "| far frame s (cold) | far frame MB | moving fps | rest to exact s | flight MB "
            "| default view dB | far view dB |")
    lines = [head, "|" + "---:|" * 14]
    for r in rows:
        dbs = []
        for key in ("psnr_view_db", "psnr_far_db"):
            v = r.get(key)
            dbs.append("does not fit" if isinstance(v, str) else
                       "identical" if key in r and v is None else _f(v, ".1f"))
        lines.append("| " + " | ".join([
            f"{r['splats']:,}", _f(value(r, "build", "seconds"), ".1f"),
            _f(value(r, "build", "peak_rss_mb"), ".0f"), _f(value(r, "open", "seconds"), ".2f"),
            _f(value(r, "open", "peak_rss_mb"), ".0f"), _f(value(r, "frame", "wall_s"), ".2f"),
            _f(value(r, "frame", "peak_rss_mb"), ".0f"), _f(value(r, "far", "wall_s"), ".2f"),
            _f(value(r, "far", "peak_rss_mb"), ".0f"), _f(value(r, "flight", "fps_median"), ".1f"),
            _f(value(r, "flight", "rest_to_exact_s"), ".2f"),
            _f(value(r, "flight", "peak_rss_mb"), ".0f"), *dbs]) + " |")
    return "\n".join(lines)


def plot(path: Path, rows: list[dict]) -> None:
    """Log-log: peak resident memory of each step (left) and the times (right) against size."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (ax_m, ax_t) = plt.subplots(1, 2, figsize=(13, 5.5))
    for label, step in MEMORY:
        pts = [(r["splats"], value(r, step, "peak_rss_mb")) for r in rows]
        pts = [p for p in pts if p[1] is not None]
        if pts:
            ax_m.plot(*zip(*pts), "-o", ms=4, label=label)
    for label, step, field, scale in TIMES:
        pts = [(r["splats"], value(r, step, field)) for r in rows]
        pts = [(n, v * scale) for n, v in pts if v is not None and v > 0]
        if pts:
            ax_t.plot(*zip(*pts), "-o", ms=4, label=label)
    for ax, label, title in ((ax_m, "peak resident MB", "memory against scene size"),
                             (ax_t, "seconds", "time against scene size")):
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("splats")
        ax.set_ylabel(label)
        ax.set_title(title)
        ax.grid(True, which="both", alpha=0.3)
        if ax.get_legend_handles_labels()[0]:
            ax.legend(fontsize=7)
    fig.tight_layout()
    save_figure(fig, path)
