"""Every layer of the quad path and the tile renderer against the per-tile reference, on the
real scenes and every camera model (docs/layers.md shows the table).

    python benchmarks/layers_table.py [--width 256 --height 192] [--models perspective,fisheye]
        [--json docs/results/layers-256x192.json] [scenes ...]

For each scene in ../shared/scenes that loads (or the scenes given) and each camera model
(the default camera, retargeted), prints a markdown row per renderer: colour PSNR, the expected
depth's largest error over the scene's depth, the normal's angle (median / 99th percentile /
max, degrees, where both alphas reach 0.5), and the shares of blended pixels whose median
depth, count or top contributor differ (:func:`splatgl.measure.evaluation.metrics.layer_errors`).
A seeded 2DGS surfel scene is added (no real 2DGS scene is shared).  No timings.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

from splatgl import RenderSettings, Renderer, RendererKind, default_camera, load_scene
from splatgl.api import render_reference_layers
from splatgl.measure.bench.machine import describe, probe_machine
from splatgl.cameras.registry import retarget
from splatgl.errors import SplatglError
from splatgl.measure.evaluation.metrics import depth_errors, image_errors, layer_errors
from splatgl.scene.splats import Scene, SplatKind
from splatgl.output.layers import Layer, with_layers

REPO = Path(__file__).resolve().parent.parent
SCENES = ["ply/donut_sh0.ply", "compressed_ply/biker.compressed.ply",
          "compressed_ply/guitar.compressed.ply", "spz/biker_v4.spz", "spz/donut_sh0_v2.spz",
          "fixtures/test64_sh3.compressed.ply"]
MODELS = ("perspective", "orthographic", "fisheye", "equirectangular")
ALL = with_layers(*Layer)


def surfel_scene(n: int = 20000, seed: int = 0) -> Scene:
    """Seeded 2DGS surfels on a bumpy sphere (normals that vary), for the surfel rows."""
    rng = np.random.default_rng(seed)
    d = rng.normal(size=(n, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    means = d * (1.0 + 0.05 * rng.normal(size=(n, 1)))
    z = np.array([0.0, 0.0, 1.0])
    axis = np.cross(z, d)
    angle = np.arccos(np.clip(d @ z, -1, 1))
    norm = np.maximum(np.linalg.norm(axis, axis=1, keepdims=True), 1e-12)
    quats = np.concatenate([np.cos(angle / 2)[:, None], np.sin(angle / 2)[:, None] * axis / norm], 1)
    return Scene(means, quats, np.log(rng.uniform(0.01, 0.04, (n, 2))), rng.normal(1.0, 1.0, n),
                 rng.normal(0.0, 0.4, (n, 1, 3)), SplatKind.SURFEL_2D)


def camera_for(scene, model: str, width: int, height: int):
    base = default_camera(scene, width, height)
    if model == "perspective":
        return base
    if model == "equirectangular":
        return retarget(base.resized(2 * height, height), model)
    return retarget(base, model)


def row(name, scene, model, kind, got, ref) -> dict:
    e = image_errors(got.rgba, ref.rgba)
    out = {"scene": name, "splats": scene.count, "model": model, "renderer": kind.value,
           "psnr": e.psnr, "max_abs": e.max_abs, **depth_errors(got, ref), **layer_errors(got, ref)}
    return out


def markdown(r: dict) -> str:
    psnr = "inf" if r["psnr"] == float("inf") else f"{r['psnr']:.1f}"
    return (f"| {r['scene']} | {r['model']} | {r['renderer']} | {psnr} | {r['depth_max_rel']:.1e} | "
            f"{r['normal_deg_median']:.3f} / {r['normal_deg_p99']:.2f} / {r['normal_deg_max']:.1f} | "
            f"{r['median_off'] * 100:.3f} | {r['count_off'] * 100:.3f} ({r['count_max_diff']:.0f}) | "
            f"{r['top_id_off'] * 100:.3f} |")


def write_picture(path: Path, out) -> None:
    """The colour and every layer's picture (as ``--layers`` writes them) side by side."""
    from splatgl.imagefiles.images import write_image
    from splatgl.imagefiles.layer_files import LayerFiles, layer_picture

    files = LayerFiles(tuple(Layer))
    pictures = [out.rgba] + [layer_picture(out, layer, files)
                             for layer in (Layer.DEPTH, Layer.MEDIAN_DEPTH, Layer.NORMAL,
                                           Layer.COUNT, Layer.TOP_ID)]
    h = max(p.shape[0] for p in pictures)
    row = [np.pad(np.clip(p[..., :3], 0, 1), ((0, h - p.shape[0]), (0, 6), (0, 0)), constant_values=1.0)
           for p in pictures]
    img = np.concatenate(row, axis=1)
    write_image(path, np.concatenate([img, np.ones(img.shape[:2] + (1,), np.float32)], -1))
    print(f"wrote {path}")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("scenes", nargs="*", type=Path)
    ap.add_argument("--width", type=int, default=256)
    ap.add_argument("--height", type=int, default=192)
    ap.add_argument("--models", default=",".join(MODELS))
    ap.add_argument("--no-surfels", action="store_true")
    ap.add_argument("--json", type=Path, default=None)
    ap.add_argument("--picture", type=Path, default=None,
                    help="also write the first scene's perspective layers as one picture (quad)")
    args = ap.parse_args(argv)
    shared = Path(__import__("os").environ.get("SPLATGL_SHARED_SCENES", REPO.parent / "shared" / "scenes"))
    paths = args.scenes or [shared / s for s in SCENES]
    scenes = []
    for path in paths:
        try:
            scenes.append((path.name, load_scene(path)))
        except SplatglError as exc:
            print(f"skip {path}: {exc}", file=sys.stderr)
    if not args.no_surfels:
        scenes.append(("surfels (seeded 2DGS)", surfel_scene()))
    settings = RenderSettings()
    rows = []
    machine = describe(probe_machine())
    print(f"{args.width}x{args.height}; {machine}")
    print("| scene | camera | renderer | colour PSNR dB | depth max err / depth | normal deg median / p99 / max "
          "| median depth off % | count off % (max diff) | top-id off % |")
    print("|---|---|---|---:|---:|---:|---:|---:|---:|")
    with Renderer() as renderer:
        for name, scene in scenes:
            for model in args.models.split(","):
                surfel = scene.kind is SplatKind.SURFEL_2D
                if surfel and model in ("fisheye", "equirectangular"):
                    continue   # 2DGS surfels: perspective and orthographic cameras only
                camera = camera_for(scene, model, args.width, args.height)
                ref = render_reference_layers(scene, camera, settings, layers=ALL)
                for kind in (RendererKind.QUAD, RendererKind.TILE):
                    if kind is RendererKind.TILE and model == "equirectangular":
                        continue   # the tile renderer draws no panoramas
                    got = renderer.render_layers(scene, camera, settings, kind, layers=ALL)
                    rows.append(row(name, scene, model, kind, got, ref))
                    print(markdown(rows[-1]), flush=True)
                    if args.picture is not None and len(rows) == 1:
                        write_picture(args.picture, got)
    if args.json is not None:
        args.json.write_text(json.dumps({"size": [args.width, args.height], "machine": machine,
                                         "rows": rows}, indent=1) + "\n")
        print(f"wrote {args.json}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
