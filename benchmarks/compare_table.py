"""The quad path and the tile renderer against the per-tile reference, on every real scene.

    python benchmarks/compare_table.py [--width 512 --height 384] [--distances 0.5,1,2]

For each scene in ../shared/scenes that loads (or the scenes given), at each default-camera
distance scale, prints a markdown table row: PSNR, SSIM, max |error| and the shares of pixels
off by more than 1/255 and 4/255, for quad and tile against the NumPy reference, and the median
time of each renderer over a few frames (quad and tile warmed up first).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from splatgl import RenderSettings, Renderer, RendererKind, default_camera, load_scene
from splatgl.measure.bench.runner import median_seconds
from splatgl.errors import SplatglError
from splatgl.measure.evaluation.metrics import image_errors
from splatgl.api import render_reference_rgba

REPO = Path(__file__).resolve().parent.parent
SCENES = ["ply/donut_sh0.ply", "compressed_ply/biker.compressed.ply",
          "compressed_ply/guitar.compressed.ply", "spz/biker_v4.spz", "spz/donut_sh0_v2.spz",
          "fixtures/test64_sh3.compressed.ply", "fixtures/minimal.splat", "fixtures/minimal.ksplat",
          "fixtures/minimal-v2.spz", "fixtures/minimal-v3.spz", "fixtures/minimal-v4.spz",
          "fixtures/minimal-raw.spz"]


def timed(fn, repeats: int):
    """``(last result, median seconds)`` of ``repeats`` calls of ``fn``."""
    seconds, out = median_seconds(fn, repeats)
    return out, seconds


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("scenes", nargs="*", type=Path)
    ap.add_argument("--width", type=int, default=512)
    ap.add_argument("--height", type=int, default=384)
    ap.add_argument("--distances", default="0.5,1,2")
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args(argv)
    paths = args.scenes or [REPO.parent / "shared" / "scenes" / s for s in SCENES]
    distances = [float(d) for d in args.distances.split(",")]
    settings = RenderSettings()
    print(f"{args.width}x{args.height}, RGBA32F, ellipse extent; times are medians of {args.repeats}")
    print("| scene | splats | SH | dist | renderer | PSNR dB | SSIM | max abs | >1/255 % | >4/255 % | ms | reference ms |")
    print("|---|---:|---:|---:|---|---:|---:|---:|---:|---:|---:|---:|")
    with Renderer() as renderer:
        for path in paths:
            try:
                scene = load_scene(path)
            except SplatglError as exc:
                print(f"skip {path}: {exc}", file=sys.stderr)
                continue
            for dist in distances:
                cam = default_camera(scene, args.width, args.height, distance_scale=dist)
                ref, t_ref = timed(lambda: render_reference_rgba(scene, cam, settings), 1)
                for kind in (RendererKind.QUAD, RendererKind.TILE):
                    try:
                        renderer.render(scene, cam, settings, kind)  # warm-up
                    except (ImportError, NotImplementedError) as exc:
                        print(f"skip {kind.value}: {exc}", file=sys.stderr)
                        continue
                    img, t = timed(lambda: renderer.render(scene, cam, settings, kind), args.repeats)
                    e = image_errors(img, ref)
                    psnr = "inf" if e.psnr == float("inf") else f"{e.psnr:.1f}"
                    print(f"| {path.name} | {scene.count} | {scene.sh_degree} | {dist:g} | {kind.value} | {psnr} | {e.ssim:.6f} | "
                          f"{e.max_abs:.4f} | {e.off_1 * 100:.3f} | {e.off_4 * 100:.3f} | "
                          f"{t * 1e3:.0f} | {t_ref * 1e3:.0f} |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
