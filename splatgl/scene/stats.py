"""Summary statistics of a scene, for ``splatgl info`` and for reasoning about camera defaults."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..constants import ALPHA_MIN
from .splats import Scene


def _vec(a: np.ndarray) -> list[float]:
    return [float(v) for v in a]


def _stats(a: np.ndarray) -> dict[str, float]:
    return {"min": float(np.min(a)), "median": float(np.median(a)), "max": float(np.max(a))}


def scene_info(scene: Scene) -> dict:
    """JSON-ready statistics of ``scene`` (plain Python numbers and lists).

    Keys: ``count``, ``kind`` ("3dgs"/"2dgs"), ``sh_degree``, ``bounds`` and ``robust_bounds``
    (``{"min": [x, y, z], "max": [x, y, z]}``, world units; robust = 1st..99th percentile of the
    means), ``opacity`` (min/median/max of the activated opacity and ``below_min_alpha``, the
    share of splats under 1/255 that can never draw a pixel), ``scale`` (min/median/max over all
    axes of the activated scales, world units) and ``anisotropy`` (median/max of the per-splat
    ratio largest / smallest scale).  A scene of zero splats has the first three keys only.
    """
    if scene.count == 0:
        return {"count": 0, "kind": scene.kind.value, "sh_degree": scene.sh_degree}
    means = scene.means.astype(np.float64)
    lo, hi = scene.robust_bounds
    opac = scene.opacities.astype(np.float64)
    scales = scene.scales.astype(np.float64)
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = scales.max(axis=1) / scales.min(axis=1)
    return {
        "count": scene.count,
        "kind": scene.kind.value,
        "sh_degree": scene.sh_degree,
        "bounds": {"min": _vec(means.min(axis=0)), "max": _vec(means.max(axis=0))},
        "robust_bounds": {"min": _vec(lo), "max": _vec(hi)},
        "opacity": {**_stats(opac), "below_min_alpha": float(np.mean(opac < ALPHA_MIN))},
        "scale": _stats(scales),
        "anisotropy": {"median": float(np.median(ratio)), "max": float(np.max(ratio))},
    }


def _fmt_vec(v: list[float]) -> str:
    return "(" + ", ".join(f"{x + 0.0:.4g}" for x in v) + ")"  # + 0.0: no "-0"


def format_info(path: str | Path, scene: Scene, info: dict) -> str:
    """A readable multi-line text block of :func:`scene_info`'s ``info`` for the file ``path``."""
    kind = {"3dgs": "3D Gaussians", "2dgs": "2DGS surfels"}.get(info["kind"], info["kind"])
    head = [f"file:        {path}" + (f" ({info['format']})" if "format" in info else ""),
            f"splats:      {info['count']} {kind}, SH degree {info['sh_degree']}"]
    if info["count"] == 0:
        return "\n".join(head + ["(an empty scene: no bounds or statistics)"])
    b, r = info["bounds"], info["robust_bounds"]
    o, s, a = info["opacity"], info["scale"], info["anisotropy"]
    extent = np.subtract(r["max"], r["min"])
    lines = [
        *head,
        f"bounds:      min {_fmt_vec(b['min'])}  max {_fmt_vec(b['max'])}",
        f"robust 1-99: min {_fmt_vec(r['min'])}  max {_fmt_vec(r['max'])}  "
        f"extent {_fmt_vec(extent)}",
        f"opacity:     min {o['min']:.4g}  median {o['median']:.4g}  max {o['max']:.4g}  "
        f"({100 * o['below_min_alpha']:.1f}% below 1/255)",
        f"scale:       min {s['min']:.4g}  median {s['median']:.4g}  max {s['max']:.4g}",
        f"anisotropy:  median {a['median']:.4g}  max {a['max']:.4g} (largest / smallest scale)",
    ]
    if "spz_axes" in info:  # an SPZ file: which axes it stores (splatgl.formats.spz_axes)
        lines.append(f"axes:        {info['spz_axes']['description']}")
    if "lod_levels" in info:  # a level-of-detail file: splats per level, the level loaded
        lv = info["lod_levels"]
        counts = ", ".join(f"{i}: {c}" for i, c in enumerate(lv["counts"]))
        shape = (f"in {lv['chunks']} chunk{'s' if lv['chunks'] != 1 else ''}" if "chunks" in lv
                 else f"of a tree with branching {lv['branching']}")  # a .lod.ply; else SOG, LCC
        lines.append(f"levels:      {len(lv['counts'])} {shape}, splats per level "
                     f"{counts} (level {lv['loaded']} shown; 0 is the finest)")
    return "\n".join(lines)
