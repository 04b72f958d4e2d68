"""docs/popping.png: one pop of the global order on a real scene, and the per-pixel order
without it (docs/fidelity.md).

The camera turns in place (yaw steps about its own centre), the cleanest trigger of popping:
nothing moves in the world and no parallax hides anything, so a renderer whose pixels depend
only on their rays draws the same world-fixed picture, while the global order, sorting by
view-space z, reorders overlapping splats as the view direction swings.  The per-pixel order
sorts along each ray, which turning does not change.  The script renders the path with the tile
renderer (global order) and the reference (per-pixel order), scores every pair with the popping
metric (splatgl/measure/evaluation/popping.py; ``own`` metric, so it needs no extra package), picks the
pair where the global order pops most, and writes, cropped around the pop and enlarged: frame
k-1, frame k and the popping error map (black 0, white >= 0.1) for each order.

    python benchmarks/popping_picture.py [--scene ply/donut_sh0.ply --up +z] [-o docs/popping.png]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

DEFAULT_SCENE, DEFAULT_UP = "ply/donut_sh0.ply", "+z"
WIDTH, HEIGHT = 400, 225
#: Camera distance (multiple of the framing distance) and yaw per frame (degrees) of the turn
#: (splatgl.measure.bench.popping_bench.camera_paths, elevation 15 degrees).
DISTANCE, YAW_STEP, FRAMES = 0.35, 3.0, 8
#: Crop margin around the popped pixels, and the enlargement.
MARGIN, ZOOM = 24, 2


def turning_cameras(scene, path: Path, up: str | None):
    from splatgl.measure.bench.popping_bench import camera_paths

    return camera_paths(scene, path, up, WIDTH, HEIGHT, FRAMES, ("turn",),
                        (DISTANCE, YAW_STEP))["turn"]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--scene", default=DEFAULT_SCENE, help="relative to the shared scenes folder")
    ap.add_argument("--up", default=DEFAULT_UP)
    ap.add_argument("-o", "--output", type=Path, default=Path("docs/popping.png"))
    args = ap.parse_args()

    from splatgl.api import Renderer
    from splatgl.measure.bench.popping_bench import render_frames
    from splatgl.measure.bench.real_scenes import shared_scenes_dir
    from splatgl.measure.evaluation.popping import POP_THRESHOLD, score_pair
    from splatgl.formats import load_scene
    from splatgl.scene.settings import Order, RendererKind, RenderSettings
    from splatgl.imagefiles.images import write_image
    from splatgl.imagefiles.pictures import _label

    path = shared_scenes_dir() / args.scene
    scene = load_scene(path)
    cams = turning_cameras(scene, path, args.up)
    orders = {"global order (tile renderer)": (RenderSettings(), RendererKind.TILE),
              "per-pixel order (reference)": (RenderSettings(order=Order.PER_PIXEL), RendererKind.REFERENCE)}
    runs = {}
    with Renderer() as renderer:
        for name, (settings, kind) in orders.items():
            frames, _ = render_frames(renderer, scene, cams, settings, kind)
            pairs = [score_pair(frames[k - 1], frames[k], k, "own") for k in range(1, len(frames))]
            runs[name] = (frames, pairs)
            print(name + ": popped per pair " + ", ".join(f"{p.popped * 100:.3f}%" for p, _ in pairs))
    glob = list(orders)[0]
    k = max(runs[glob][1], key=lambda pe: pe[0].popped)[0].index
    err = runs[glob][1][k - 1][1]
    ys, xs = np.nonzero(err > POP_THRESHOLD["own"])
    if not len(ys):
        raise SystemExit("no pop found on this path")
    y0, y1 = max(ys.min() - MARGIN, 0), min(ys.max() + MARGIN + 1, HEIGHT)
    x0, x1 = max(xs.min() - MARGIN, 0), min(xs.max() + MARGIN + 1, WIDTH)
    rows = []
    for name in orders:
        frames, pairs = runs[name]
        e = np.clip(pairs[k - 1][1] / POP_THRESHOLD["own"], 0, 1)
        tiles = [frames[k - 1].rgb, frames[k].rgb, np.dstack([e, e, e])]
        row = np.concatenate([np.kron(np.clip(t[y0:y1, x0:x1], 0, 1), np.ones((ZOOM, ZOOM, 1)))
                              for t in tiles], 1)
        row = _label(np.ascontiguousarray(row, np.float32), 4, 16,
                     f"{name}: frames {k - 1}, {k}, popping ({pairs[k - 1][0].popped * 100:.2f}% of the pixels)")
        rows.append(row)
    picture = np.concatenate(rows, 0)
    write_image(args.output, np.concatenate([picture, np.ones(picture.shape[:2] + (1,), np.float32)], -1))
    print(f"wrote {args.output}: pair {k - 1}-{k}, crop x {x0}-{x1}, y {y0}-{y1}")


if __name__ == "__main__":
    main()
