"""Level-of-detail benchmark: frame time and error against full detail along two paths.

For a real-data scene (:func:`splatgl.bench.scale.scene_file`) and its hierarchy (built once
and cached as ``.lod.ply`` beside it), render an orbit at the framing distance and a
fly-through from far (FLY_FAR x the framing distance) to close (FLY_NEAR x), at full detail
(the plain quad path) and with several cuts (pixel thresholds and splat budgets).  Per frame:
frame time, nodes in the cut, cut-selection time, PSNR and SSIM against the full-detail frame.
Popping: between consecutive frames the change the LOD adds beyond full detail's own change,
``(L[k+1] - L[k]) - (F[k+1] - F[k])``, as a PSNR (higher: smoother).

Run: ``python -m splatgl.bench.lod_bench --sizes 3M,6M --out DIR`` (table, lod.json,
lod.png: the Pareto plot of frame time against RMS error per path).
"""

from __future__ import annotations

import argparse
import json
import math
import statistics
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
from .report import save_figure

#: Fly-through distances, in multiples of the framing distance.
FLY_FAR, FLY_NEAR = 6.0, 0.5
#: Frames with at least this distance multiple count as far views.
FAR_FROM = 3.0


@dataclass(frozen=True)
class LodFrame:
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


def _psnr(mse: float) -> float | None:
    return None if mse <= 0 else float(-10.0 * math.log10(mse))


def cameras(scene, width: int, height: int, frames: int):
    """{path name: [(distance multiple, camera)]}: an orbit and a far-to-close fly-through."""
    from ..camera import orbit
    from ..render import default_camera

    base = default_camera(scene, width, height)
    centre = 0.5 * (scene.robust_bounds[0] + scene.robust_bounds[1])
    dist = float(np.linalg.norm(base.center - centre))
    orbit_cams = [(1.0, base.with_pose(orbit(centre, dist, 90.0 * i / max(frames - 1, 1), 20.0)))
                  for i in range(frames)]
    fly = []
    for i in range(frames):
        m = FLY_FAR * (FLY_NEAR / FLY_FAR) ** (i / max(frames - 1, 1))  # geometric steps
        fly.append((m, base.with_pose(orbit(centre, dist * m, 10.0, 20.0))))
    return {"orbit": orbit_cams, "fly": fly}


def lod_file(scene_path: Path) -> Path:
    """The cached .lod.ply of ``scene_path`` (built with branching 4 on first use)."""
    out = scene_path.with_name(scene_path.stem + ".lod.ply")
    if not out.is_file():
        from ..formats import load_scene
        from ..lod.build import build_hierarchy
        from ..lod.io import write_lod
        write_lod(out, build_hierarchy(load_scene(scene_path)))
    return out


def bench_lod(scene_path: Path, width: int, height: int, frames: int, thresholds, budgets,
              log=print) -> list[LodFrame]:
    from ..formats import load_scene
    from ..gl.context import create_headless_context
    from ..lod.io import read_lod
    from ..lod.render import LodRenderer, LodSettings
    from ..metrics import ssim
    from ..quad import QuadRenderer
    from ..settings import RenderSettings

    tree = read_lod(lod_file(scene_path))
    n = tree.level_size(0)
    name = f"{n / 1e6:g}M"
    leaves = load_scene(scene_path)
    ctx = create_headless_context()
    settings = RenderSettings()
    paths = cameras(leaves, width, height, frames)
    full = QuadRenderer(ctx, leaves, settings)
    reference = {}
    for path, cams in paths.items():
        full.render(cams[0][1])  # warm-up: programs, cull data
        imgs, ms = [], []
        for _, cam in cams:
            imgs.append(full.render(cam)[..., :3].astype(np.float64))
            ms.append(full.last_times.total * 1e3)
        reference[path] = (imgs, ms)
        log(f"lod bench {name} {path}: full detail {statistics.median(ms):.0f} ms median")
    full.release()
    configs = [(f"T={t:g}px", LodSettings(threshold_px=t)) for t in thresholds]
    configs += [(f"budget={b:,}", LodSettings(threshold_px=min(thresholds), budget=b)) for b in budgets]
    rows = []
    for label, lod in configs:
        r = LodRenderer(ctx, tree, settings, lod)
        for path, cams in paths.items():
            imgs, ms = reference[path]
            r.render(cams[0][1])
            prev = None
            for k, (m, cam) in enumerate(cams):
                img = r.render(cam)[..., :3].astype(np.float64)
                t = r.last_times
                mse = float(np.mean((img - imgs[k]) ** 2))
                pop = None
                if prev is not None:
                    pop = _psnr(float(np.mean(((img - prev) - (imgs[k] - imgs[k - 1])) ** 2)))
                prev = img
                rows.append(LodFrame(name, path, label, k, m, t.total * 1e3, ms[k], t.drawn,
                                     r.last_cut_nodes, r.last_cut_s * 1e3, _psnr(mse),
                                     ssim(img.astype(np.float32), imgs[k].astype(np.float32)), pop))
            log(f"lod bench {name} {path} {label}: done")
        r.release()
    ctx.release()
    return rows


def summary(rows: list[LodFrame]) -> list[dict]:
    """Per (scene, path, config): median frame ms, median full ms, far-view speed-up (median
    of full / LOD over frames at >= FAR_FROM x), the slowest frame's LOD / full ratio, worst
    PSNR and SSIM, worst popping PSNR, median cut nodes and cut ms."""
    out = []
    keys = dict.fromkeys((r.scene, r.path, r.config) for r in rows)
    for scene, path, config in keys:
        sub = [r for r in rows if (r.scene, r.path, r.config) == (scene, path, config)]
        far = [r.full_ms / r.frame_ms for r in sub if r.distance >= FAR_FROM]
        psnrs = [r.psnr if r.psnr is not None else float("inf") for r in sub]
        pops = [r.popping_psnr for r in sub if r.popping_psnr is not None]
        out.append({
            "scene": scene, "path": path, "config": config,
            "frame_ms": statistics.median(r.frame_ms for r in sub),
            "full_ms": statistics.median(r.full_ms for r in sub),
            "far_speedup": statistics.median(far) if far else None,
            "slowest_ratio": max(r.frame_ms / r.full_ms for r in sub),
            "min_psnr": min(psnrs), "min_ssim": min(r.ssim for r in sub),
            "min_popping_psnr": min(pops) if pops else None,
            "cut_nodes": statistics.median(r.cut_nodes for r in sub),
            "cut_ms": statistics.median(r.cut_ms for r in sub),
        })
    return out


def table(summ: list[dict]) -> str:
    f = lambda v, s: "-" if v is None else ("inf" if isinstance(v, float) and math.isinf(v) else format(v, s))
    out = [f"{'scene':>5} {'path':>5} {'config':>16} {'ms':>8} {'full ms':>8} {'far x':>6} "
           f"{'max LOD/full':>12} {'min PSNR':>8} {'min SSIM':>8} {'pop PSNR':>8} {'cut nodes':>10} {'cut ms':>7}"]
    for s in summ:
        out.append(f"{s['scene']:>5} {s['path']:>5} {s['config']:>16} {s['frame_ms']:>8.0f} "
                   f"{s['full_ms']:>8.0f} {f(s['far_speedup'], '.2f'):>6} {s['slowest_ratio']:>12.2f} "
                   f"{f(s['min_psnr'], '.1f'):>8} {s['min_ssim']:>8.4f} "
                   f"{f(s['min_popping_psnr'], '.1f'):>8} {s['cut_nodes']:>10,.0f} {s['cut_ms']:>7.0f}")
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


def main(argv=None) -> int:
    from .scale import scene_file
    from .scale_cli import parse_sizes

    p = argparse.ArgumentParser(prog="python -m splatgl.bench.lod_bench", description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--sizes", default="3M,6M", help="scene sizes (default 3M,6M)")
    p.add_argument("--width", type=int, default=1280)
    p.add_argument("--height", type=int, default=720)
    p.add_argument("--frames", type=int, default=5, help="frames per path (default 5)")
    p.add_argument("--thresholds", default="1,2", help="pixel thresholds (default 1,2)")
    p.add_argument("--budgets", default="1M,0.3M", help="splat budgets (default 1M,0.3M)")
    p.add_argument("--out", type=Path, default=None)
    args = p.parse_args(argv)
    thresholds = [float(t) for t in args.thresholds.split(",")]
    budgets = list(parse_sizes(args.budgets, (), "--budgets"))
    rows = []
    for n in parse_sizes(args.sizes, (), "--sizes"):
        t0 = time.perf_counter()
        path = scene_file(n, 0)
        lod_file(path)
        print(f"lod bench: {n:,} splats ready ({time.perf_counter() - t0:.0f} s)", flush=True)
        rows += bench_lod(path, args.width, args.height, args.frames, thresholds, budgets,
                          log=lambda m: print(m, flush=True))
    summ = summary(rows)
    print(table(summ))
    if args.out is not None:
        args.out.mkdir(parents=True, exist_ok=True)
        (args.out / "lod.json").write_text(json.dumps({"summary": summ, "frames": [asdict(r) for r in rows]},
                                                      indent=1) + "\n")
        plot(args.out / "lod.png", rows)
        print(f"wrote {args.out / 'lod.json'}, lod.png")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
