"""Scale benchmark output: a table, JSON, the log-log growth slopes and a log-log plot."""

from __future__ import annotations

import json
import math
from dataclasses import asdict
from pathlib import Path

import numpy as np

from .scale import ScaleRow  # noqa: F401 (annotations)
from ...writing.atomic import atomic_write_text
from .report import save_figure

#: The figures whose growth with the splat count is fitted and plotted: (label, getter).
SERIES = (
    ("quad frame (ms)", lambda r: r.quad_frame_ms),
    ("cull (ms)", lambda r: r.stages_ms.get("cull")),
    ("sort CPU (ms)", lambda r: r.stages_ms.get("sort")),
    ("sort GPU (ms)", lambda r: r.sort_gpu_ms),
    ("draw (ms)", lambda r: r.stages_ms.get("draw")),
    ("tile frame (ms)", lambda r: r.tile_frame_ms),
    ("peak RSS (MB)", lambda r: r.rss_peak_mb),
    ("load (s)", lambda r: r.load_s),
)


def loglog_slope(xs, ys) -> float | None:
    """Least-squares slope of log(y) against log(x) (cost ~ x^slope); None under 2 points."""
    pts = [(x, y) for x, y in zip(xs, ys) if y is not None and y > 0]
    if len(pts) < 2 or len({x for x, _ in pts}) < 2:
        return None
    lx, ly = np.log([p[0] for p in pts]), np.log([p[1] for p in pts])
    return float(np.polyfit(lx, ly, 1)[0])


def slopes(rows: list[ScaleRow]) -> dict[str, dict[str, float | None]]:
    """Per resolution ("WxH"), the log-log slope of each :data:`SERIES` over the SH0 rows."""
    out = {}
    for w, h in dict.fromkeys((r.width, r.height) for r in rows):
        sub = sorted((r for r in rows if (r.width, r.height) == (w, h) and r.sh_degree == 0),
                     key=lambda r: r.splats)
        out[f"{w}x{h}"] = {name: loglog_slope([r.splats for r in sub], [get(r) for r in sub])
                           for name, get in SERIES}
    return out


def _f(v, spec):
    return "-" if v is None or (isinstance(v, float) and math.isnan(v)) else format(v, spec)


def table(rows: list[ScaleRow]) -> str:
    head = (f"{'splats':>9} {'SH':>2} {'size':>9} {'load s':>6} {'RSS load':>8} {'RSS peak':>8} "
            f"{'xdecoded':>8} {'GPU B/spl':>9} {'visible':>9} {'cull':>7} {'sort':>7} "
            f"{'sortGPU':>8} {'prepass':>7} {'draw':>8} {'quad ms':>8} {'tile ms':>8} {'same':>4} "
            f"{'cmp B/spl':>9} {'cmp PSNR':>8}")
    out = [head]
    for r in rows:
        out.append(
            f"{r.splats:>9,} {r.sh_degree:>2} {f'{r.width}x{r.height}':>9} {r.load_s:>6.2f} "
            f"{r.rss_load_mb:>8.0f} {r.rss_peak_mb:>8.0f} {r.rss_load_mb / r.decoded_mb:>8.2f} "
            f"{r.gpu_bytes_per_splat:>9.0f} {r.visible:>9,} {r.stages_ms['cull']:>7.1f} "
            f"{r.stages_ms['sort']:>7.1f} {_f(r.sort_gpu_ms, '8.1f'):>8} "
            f"{r.stages_ms['prepass']:>7.1f} {r.stages_ms['draw']:>8.1f} {r.quad_frame_ms:>8.1f} "
            f"{_f(r.tile_frame_ms, '8.1f'):>8} {_f(r.gpu_sort_identical, ''):>4} "
            f"{_f(r.compact_bytes_per_splat, '9.0f'):>9} {_f(r.compact_psnr, '8.1f'):>8}")
    if rows:
        out.append("cull: " + ("the compiled kernel (numba)" if all(r.cull_compiled for r in rows)
                               else "NumPy" if not any(r.cull_compiled for r in rows)
                               else "compiled on some rows, NumPy on others"))
    if any(r.compact_bytes_per_splat for r in rows):
        out.append("cmp: --gpu-storage compact, its GPU bytes per splat and the PSNR (dB) of its "
                   "last frame against the measured storage's")
    for res, fits in slopes(rows).items():
        text = ", ".join(f"{name} {_f(s, '.2f')}" for name, s in fits.items())
        out.append(f"log-log slope over the SH0 sizes at {res}: {text}")
    return "\n".join(out)


def write_json(path: Path, rows: list[ScaleRow], extra: dict) -> None:
    doc = {**extra, "slopes": slopes(rows), "rows": [asdict(r) for r in rows]}
    atomic_write_text(path, json.dumps(doc, indent=1) + "\n")


def plot(path: Path, rows: list[ScaleRow]) -> None:
    """Log-log: time figures (left) and memory (right) against the splat count, SH0 rows, one
    line per resolution and figure; fitted slopes in the legend."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (ax_t, ax_m) = plt.subplots(1, 2, figsize=(14, 5.5))
    fits = slopes(rows)
    for (w, h), style in zip(dict.fromkeys((r.width, r.height) for r in rows), ("-o", "--s", ":^")):
        sub = sorted((r for r in rows if (r.width, r.height) == (w, h) and r.sh_degree == 0),
                     key=lambda r: r.splats)
        res = f"{w}x{h}"
        for name, get in SERIES:
            pts = [(r.splats, get(r)) for r in sub if get(r) is not None]
            if not pts:
                continue
            ax = ax_m if "RSS" in name else ax_t
            s = fits[res][name]
            ax.plot(*zip(*pts), style, ms=4, label=f"{name} {res} (slope {_f(s, '.2f')})")
    for ax, label in ((ax_t, "milliseconds (load: seconds)"), (ax_m, "MB")):
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("splats")
        ax.set_ylabel(label)
        ax.grid(True, which="both", alpha=0.3)
        if ax.get_legend_handles_labels()[0]:  # SH3-only runs plot nothing
            ax.legend(fontsize=7)
    ax_t.set_title("time against scene size")
    ax_m.set_title("peak resident memory against scene size")
    fig.tight_layout()
    save_figure(fig, path)


def merge_reports(paths: list[Path]) -> tuple[list[ScaleRow], dict]:
    """The rows of the scale.json files ``paths`` (e.g. one run per size), sorted by size, SH
    degree and width, and their other fields merged (later files win)."""
    from .scale import ScaleRow

    rows, extra = [], {}
    for path in paths:
        doc = json.loads(Path(path).read_text())
        rows += [ScaleRow(**r) for r in doc.pop("rows")]
        doc.pop("slopes", None)
        extra.update(doc)
    rows.sort(key=lambda r: (r.splats, r.sh_degree, r.width))
    return rows, extra
