"""Level-of-detail benchmark: frame time and error against full detail along camera paths.

For a real-data scene (:func:`splatgl.measure.bench.scale.scene_file`) and its hierarchy (built once
and cached as ``.lod.ply`` beside it), render camera paths at full detail (the plain quad
path) and with several cuts (pixel thresholds with and without a transition band, splat
budgets).  Paths: ``orbit`` at the framing distance and ``fly`` from far (FLY_FAR x the framing
distance) to close (FLY_NEAR x), in a few large steps (frame time and error); for popping,
``fly-fine`` (FINE_STEP closer a frame from FINE_FAR x) and ``orbit-fine`` (FINE_DEGREES a
frame at FINE_FAR x), in small steps such as an animation takes; ``fly-switch`` (FINE_STEP
closer a frame across the distance where the first configuration's cut gives way to the leaves,
:func:`switch_distance`), the one change the transition band does not smooth.  Per frame: frame time, nodes
in the cut, cut-selection time, PSNR and SSIM against the full-detail frame, and between
consecutive frames the change the LOD adds beyond full detail's own change,
``D = (L[k+1] - L[k]) - (F[k+1] - F[k])`` (max and mean of ``|D|`` over pixels and RGB, and as
a PSNR), beside full detail's own change ``|F[k+1] - F[k]|``; and the change the cut alone
makes, ``|L[k+1] - L'[k+1]|`` with ``L'[k+1]`` drawn at frame k+1's camera through frame k's
cut (its nodes and weights): ``D`` also holds how the LOD's approximation error moves with
the view, this does not.

Run: ``splatgl bench --lod --sizes 3M,6M --out DIR`` (its options:
:mod:`splatgl.commands._bench_modes`): table, lod.json, lod.png (the Pareto plot of frame time
against RMS error per path; the summary, table and plot are :mod:`splatgl.measure.bench.lod_report`).
"""

from __future__ import annotations

import json
import math
import statistics
import time
from dataclasses import asdict
from pathlib import Path

import numpy as np

from .lod_report import LodFrame, plot, summary, table

#: Fly-through distances, in multiples of the framing distance.
FLY_FAR, FLY_NEAR = 6.0, 0.5
#: Fine paths (popping): start distance multiple, fly-in factor per frame, orbit degrees per frame.
FINE_FAR, FINE_STEP, FINE_DEGREES = 6.0, 0.97, 1.0
#: Path sets: coarse (time and error from far to close), fine (popping between frames) and
#: switch (popping where the renderer switches from the cut to drawing the leaves).
PATH_SETS = ("coarse", "fine", "switch")


def _psnr(mse: float) -> float | None:
    return None if mse <= 0 else float(-10.0 * math.log10(mse))


def cameras(scene, width: int, height: int, frames: int, paths: str = "coarse",
            switch_at: float | None = None):
    """{path name: [(distance multiple, camera)]}: ``coarse``: an orbit over 90 degrees and a
    far-to-close fly-through in ``frames`` frames each; ``fine``: a fly-in and an orbit in
    small steps (FINE_STEP, FINE_DEGREES) from FINE_FAR x the framing distance; ``switch``: a
    fly-in in FINE_STEP steps whose middle frame is at the distance multiple ``switch_at``."""
    from ...cameras.poses import orbit
    from ...api import default_camera

    base = default_camera(scene, width, height)
    centre = 0.5 * (scene.robust_bounds[0] + scene.robust_bounds[1])
    dist = float(np.linalg.norm(base.center - centre))
    at = lambda m, deg: (m, base.with_pose(orbit(centre, dist * m, deg, 20.0)))
    if paths == "switch":
        return {"fly-switch": [at(switch_at * FINE_STEP ** (i - frames // 2), 10.0)
                               for i in range(frames)]}
    if paths == "fine":
        return {"fly-fine": [at(FINE_FAR * FINE_STEP ** i, 10.0) for i in range(frames)],
                "orbit-fine": [at(FINE_FAR, 10.0 + FINE_DEGREES * i) for i in range(frames)]}
    span = max(frames - 1, 1)
    return {"orbit": [at(1.0, 90.0 * i / span) for i in range(frames)],
            "fly": [at(FLY_FAR * (FLY_NEAR / FLY_FAR) ** (i / span), 10.0)  # geometric steps
                    for i in range(frames)]}


def switch_distance(scene, tree, width: int, height: int, lod, lo: float = 0.05,
                    hi: float = 64.0) -> float:
    """The distance multiple (on the fly-through's line) at which ``lod``'s cut first gives way
    to the leaves (:func:`splatgl.lod.selection.threshold_cut` returns None) when flying in: a
    bisection on the log distance to 1%, returning its nearer end, which draws the leaves (so
    a switch path's middle frame does, and the frame one FINE_STEP farther, beyond the 1%
    bracket, draws a cut).  ``hi`` when even that far draws the leaves, ``lo`` when even that
    close draws a cut."""
    from ...lod.cut import CutData
    from ...lod.selection import threshold_cut

    data = CutData.from_tree(tree)
    leaves = lambda m: threshold_cut(tree, data, cameras(scene, width, height, 1, "switch", m)
                                     ["fly-switch"][0][1], lod)[0] is None
    if leaves(hi):
        return hi
    if not leaves(lo):
        return lo
    while hi / lo > 1.01:  # leaves(lo), not leaves(hi)
        mid = math.sqrt(lo * hi)
        lo, hi = (mid, hi) if leaves(mid) else (lo, mid)
    return lo


def lod_file(scene_path: Path) -> Path:
    """The cached .lod.ply of ``scene_path`` (built with branching 4 on first use)."""
    out = scene_path.with_name(scene_path.stem + ".lod.ply")
    if not out.is_file():
        from ...formats import load_scene
        from ...lod.build import build_hierarchy
        from ...lod.io import write_lod
        write_lod(out, build_hierarchy(load_scene(scene_path)))
    return out


def configurations(thresholds, budgets, bands) -> list[tuple[str, object]]:
    """(label, LodSettings): every threshold at every band, then the budgets at the first band
    (never finer than the smallest threshold)."""
    from ...lod.selection import LodSettings

    name = lambda b: "" if b == bands[0] else (" hard" if b == 1 else f" band {b:g}")
    out = [(f"T={t:g}px{name(b)}", LodSettings(threshold_px=t, band=b)) for t in thresholds for b in bands]
    out += [(f"budget={n:,}", LodSettings(threshold_px=min(thresholds), budget=n, band=bands[0]))
            for n in budgets]
    return out


def bench_lod(scene_path: Path, width: int, height: int, frames: int, thresholds, budgets,
              log=print, bands=(2.0,), paths: str = "coarse",
              cut_change: bool | None = None) -> list[LodFrame]:
    """Rows per (config, path, frame).  ``cut_change`` (default: on for the fine paths) also
    draws each frame through the previous frame's cut (one more render a frame)."""
    if cut_change is None:
        cut_change = paths != "coarse"
    from ...formats import load_scene
    from ...gl.context import create_headless_context
    from ...lod.io import read_lod
    from ...cameras.view import View
    from ...lod.source import lod_renderer
    from ..evaluation.metrics import ssim
    from ...renderers.quad import QuadRenderer
    from ...scene.settings import RenderSettings

    tree = read_lod(lod_file(scene_path))
    n = tree.level_size(0)
    name = f"{n / 1e6:g}M"
    leaves = load_scene(scene_path)
    ctx = create_headless_context()
    settings = RenderSettings()
    configs = configurations(thresholds, budgets, bands)
    switch_at = None
    if paths == "switch":  # centred on the first configuration's switch
        switch_at = switch_distance(leaves, tree, width, height, configs[0][1])
        log(f"lod bench {name}: {configs[0][0]} switches to the leaves at {switch_at:.3g}x "
            "the framing distance")
    paths = cameras(leaves, width, height, frames, paths, switch_at)
    full = QuadRenderer(ctx, leaves, settings)
    reference = {}
    for path, cams in paths.items():
        full.render(View.of(cams[0][1], settings, leaves))  # warm-up: programs, cull data
        imgs, ms = [], []
        for _, cam in cams:
            imgs.append(full.render(View.of(cam, settings, leaves)).rgba[..., :3].astype(np.float64))
            ms.append(full.last_times.total * 1e3)
        reference[path] = (imgs, ms)
        log(f"lod bench {name} {path}: full detail {statistics.median(ms):.0f} ms median")
    full.release()
    rows = []
    for label, lod in configs:
        r = lod_renderer(ctx, tree, settings, lod)
        cut_of = r.rows
        view = lambda cam: View.of(cam, settings, tree.nodes)  # noqa: E731
        for path, cams in paths.items():
            imgs, ms = reference[path]
            r.render(view(cams[0][1]))
            prev = prev_cut = None
            for k, (m, cam) in enumerate(cams):
                img = r.render(view(cam)).rgba[..., :3].astype(np.float64)
                t, cut = r.last_times, cut_of.last_cut
                frame = dict(scene=name, path=path, config=label, frame=k, distance=m,
                             frame_ms=t.total * 1e3, full_ms=ms[k], drawn=t.drawn,
                             cut_nodes=cut_of.last_cut_nodes, cut_ms=cut_of.last_cut_s * 1e3,
                             leaves=cut_of.last_drew_leaves,
                             psnr=_psnr(float(np.mean((img - imgs[k]) ** 2))),
                             ssim=ssim(img.astype(np.float32), imgs[k].astype(np.float32)),
                             popping_psnr=None)
                if prev is not None:
                    own = imgs[k] - imgs[k - 1]
                    d = np.abs((img - prev) - own)
                    frame.update(popping_psnr=_psnr(float(np.mean(d * d))), pop_max=float(d.max()),
                                 pop_mean=float(d.mean()), full_change_max=float(np.abs(own).max()),
                                 full_change_mean=float(np.abs(own).mean()))
                    if cut_change:
                        cut_of.cut_override = prev_cut  # this camera, the previous frame's cut
                        frozen = np.abs(img - r.render(view(cam)).rgba[..., :3].astype(np.float64))
                        cut_of.cut_override = None
                        frame.update(cut_change_max=float(frozen.max()),
                                     cut_change_mean=float(frozen.mean()))
                prev, prev_cut = img, cut
                rows.append(LodFrame(**frame))
            log(f"lod bench {name} {path} {label}: done")
        r.release()
    ctx.release()
    return rows


def run_lod(sizes, width: int, height: int, frames: int, thresholds, budgets, bands,
            paths: str = "coarse", out: Path | None = None, log=print) -> list[dict]:
    """Measure every size (scene and hierarchy built and cached on first use), print the table,
    and with ``out`` write lod.json and lod.png there (each atomically); the summary rows."""
    from ...order import kernels as cull_kernel
    from ...writing.outputs import OutputFiles
    from .scale import scene_file

    from .machine import describe, probe_machine

    cull_kernel.kernel(wait=True)  # where installed, every timed frame takes the compiled kernels
    machine = probe_machine()
    log(describe(machine))
    rows = []
    for n in sizes:
        t0 = time.perf_counter()
        path = scene_file(n, 0)
        lod_file(path)
        log(f"lod bench: {n:,} splats ready ({time.perf_counter() - t0:.0f} s)")
        rows += bench_lod(path, width, height, frames, thresholds, budgets, log=log, bands=bands,
                          paths=paths)
    summ = summary(rows)
    log(table(summ))
    if out is not None:
        out.mkdir(parents=True, exist_ok=True)
        # checked by the command before measuring: an existing file here means --force
        files = OutputFiles({name: out / name for name in ("lod.json", "lod.png")}, overwrite=True)
        with files:
            files.temp("lod.json").write_text(json.dumps(
                {"machine": machine, "summary": summ, "frames": [asdict(r) for r in rows]},
                indent=1) + "\n")
            plot(files.temp("lod.png"), rows)
        log(f"wrote {out / 'lod.json'}, lod.png")
    return summ
