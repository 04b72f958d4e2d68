"""The interactive benchmark's output: its table, its JSON and its plot (:mod:`.flight`)."""

from __future__ import annotations

import json
from pathlib import Path

from ...writing.atomic import atomic_write_text
from .flight import MOVE_END, ORBIT_END, FlightResult
from .report import save_figure

#: The targets of issue 27 on a 2-core llvmpipe machine at 1280x720.
TARGET_FPS_MEDIAN, TARGET_FPS_P10 = 10.0, 7.0
TARGET_PSNR, TARGET_EXACT_S, TARGET_LATENCY_S = 30.0, 3.0, 0.150


def table(results: list[FlightResult]) -> str:
    """One line per scene: moving fps (median, 10th percentile), PSNR of the moving frames
    (median, worst), rest to exact, the exact frame's own time, input latency (median, worst),
    and whether the exact frame is ``splatgl render``'s."""
    head = (f"{'scene':>12} {'splats':>9} {'frames':>6} {'fps med':>7} {'fps p10':>7} "
            f"{'PSNR med':>8} {'PSNR min':>8} {'exact s':>7} {'full s':>6} {'lat med':>7} "
            f"{'lat max':>7} {'LOD s':>6} {'same':>4}")
    lines = [head]
    for r in results:
        s = r.summary()
        f = lambda v, spec: "-" if v is None else format(v, spec)  # noqa: E731
        lines.append(
            f"{s['scene']:>12} {s['splats']:>9,} {s['frames']:>6} {s['fps_median']:>7.1f} "
            f"{s['fps_p10']:>7.1f} {f(s['psnr_median'], '.1f'):>8} {f(s['psnr_min'], '.1f'):>8} "
            f"{s['rest_to_exact']:>7.2f} {s['exact_seconds']:>6.2f} "
            f"{f(s['latency_median'] and s['latency_median'] * 1e3, '.0f'):>5}ms "
            f"{f(s['latency_max'] and s['latency_max'] * 1e3, '.0f'):>5}ms {s['lod_seconds']:>6.2f} "
            f"{'yes' if s['exact_matches_render'] else 'NO':>4}")
    lines.append(f"targets: fps median >= {TARGET_FPS_MEDIAN:g}, p10 >= {TARGET_FPS_P10:g}, moving "
                 f"PSNR >= {TARGET_PSNR:g} dB (shared scenes), exact <= {TARGET_EXACT_S:g} s after "
                 f"rest, latency < {TARGET_LATENCY_S * 1e3:.0f} ms")
    return "\n".join(lines)


def write_json(path: Path, results: list[FlightResult], extra: dict) -> None:
    doc = {**extra, "summary": [r.summary() for r in results],
           "flights": [r.to_dict() for r in results]}
    atomic_write_text(path, json.dumps(doc, indent=1) + "\n")


def plot(path: Path, results: list[FlightResult]) -> None:
    """Frame time (top) and the moving frames' PSNR (bottom) over the flight, one line per
    scene; the phases (orbit, fly-in) and the budget marked."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (top, bottom) = plt.subplots(2, 1, figsize=(10, 7), sharex=True)
    for r in results:
        t = [f.t for f in r.frames]
        top.plot(t, [f.seconds * 1e3 for f in r.frames], lw=1, label=f"{r.scene} ({r.splats:,})")
        scored = [(f.t, f.psnr if f.psnr is not None else 60.0) for f in r.frames if f.psnr is not None
                  or f.scale == 1.0 and f.budget is None]
        if scored:
            bottom.plot(*zip(*scored), lw=1, marker=".", ms=3, label=r.scene)
    if results:
        top.axhline(1e3 / results[0].target_fps, ls="--", c="gray", lw=1, label="budget")
    bottom.axhline(TARGET_PSNR, ls=":", c="red", lw=1, label=f"{TARGET_PSNR:g} dB")
    for ax in (top, bottom):
        for x in (ORBIT_END, MOVE_END):
            ax.axvline(x, c="k", lw=0.5, alpha=0.4)
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=7, loc="upper right")
    top.set_ylabel("frame time (ms)")
    top.set_title("interactive flight: orbit (0-5 s), fly-in (5-8 s), then rest")
    bottom.set_ylabel("PSNR against exact (dB)")
    bottom.set_xlabel("flight time (s)")
    fig.tight_layout()
    save_figure(fig, path)
