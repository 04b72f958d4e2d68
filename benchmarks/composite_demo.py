"""Splats composited into a mesh render by depth (``splatgl render --under``): the picture in
docs/layers.md and its accuracy figures.

    python benchmarks/composite_demo.py [SCENE] [--width 640 --height 480]
        [--picture docs/composite.png] [--out docs/results/composite.md]

A box and a floor plane are placed inside a real scene (sized from its robust bounds) and drawn
by the project's mesh rasterizer (splatgl.renderers.mesh) into colour and view z; the scene is
composited into that render by the quad path, the tile renderer and the reference.  Figures:

1. mesh depth against ray casting (splatgl.splatmath.mesh.ray_depth): coverage and relative error;
2. a plane at the median view z of the splats, a closed form: the composite must equal the
   splats in front of the plane drawn over the plane's colour (the splats behind it made
   transparent, so anchor and near plane stay the same);
3. the box composite of quad and tile against the reference's.

No timings (the machine is shared).
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

import numpy as np

from splatgl import RenderSettings, Renderer, RendererKind, default_camera, load_scene
from splatgl.api import render_reference_layers
from splatgl.measure.bench.machine import describe, probe_machine
from splatgl.cameras.view import View
from splatgl.scene.splats import Scene
from splatgl.measure.evaluation.metrics import image_errors
from splatgl.imagefiles.images import write_image
from splatgl.output.layers import Layer, with_layers
from splatgl.imagefiles.pictures import _label
from splatgl.output.under import DepthKind, UnderImage
from splatgl.renderers.mesh import MeshRenderer
from splatgl.splatmath import mesh as meshes
from splatgl.splatmath import project as pm

REPO = Path(__file__).resolve().parent.parent
DEFAULT_SCENE = "compressed_ply/guitar.compressed.ply"
LAYERS = with_layers(Layer.DEPTH)


def shapes(scene, camera):
    """A box beside the scene's centre, half in it, and a floor under it (world units)."""
    lo, hi = scene.robust_bounds
    centre, size = 0.5 * (lo + hi), hi - lo
    span = float(np.linalg.norm(size))
    down = np.asarray(camera.rotation)[1]             # image down, in world axes
    right = np.asarray(camera.rotation)[0]
    box = meshes.box(centre + 0.18 * span * right, 0.28 * span, (0.85, 0.45, 0.2),
                     rotation=pm.quat_to_rotmat(np.array([0.92, 0.1, 0.35, 0.1])))
    forward = np.cross(right, down)
    corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
    bottom = float(((corners - centre) @ down).max())   # the scene's lowest point on screen
    floor = meshes.plane(centre + bottom * down, 0.9 * span * right, 0.9 * span * forward,
                         (0.6, 0.65, 0.75))
    return box + floor


def hide(scene, rows):
    """``scene`` with ``rows`` made fully transparent (opacity logit -40: alpha below 1/255
    everywhere, so never blended), everything else (its anchor, its near plane) kept."""
    logits = np.where(rows, -40.0, scene.opacity_logits)
    return Scene(scene.means, scene.quats, scene.log_scales, logits, scene.sh, scene.kind)


def errors_row(name, got, ref) -> str:
    e = image_errors(got, ref)
    psnr = "inf" if e.psnr == float("inf") else f"{e.psnr:.1f}"
    return f"| {name} | {psnr} | {e.max_abs:.4f} | {e.off_1 * 100:.3f} |"


def labelled(img, text):
    """The image under a dark bar holding ``text``."""
    rgb = np.clip(img[..., :3], 0, 1).astype(np.float32)
    bar = _label(np.full((24, rgb.shape[1], 3), 0.15, np.float32), 6, 18, text, 16)
    return np.concatenate([bar, rgb], axis=0)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("scene", nargs="?", type=Path)
    ap.add_argument("--width", type=int, default=640)
    ap.add_argument("--height", type=int, default=480)
    ap.add_argument("--distance", type=float, default=0.8)
    ap.add_argument("--picture", type=Path, default=None)
    ap.add_argument("--out", type=Path, default=None)
    args = ap.parse_args(argv)
    shared = Path(os.environ.get("SPLATGL_SHARED_SCENES", REPO.parent / "shared" / "scenes"))
    path = args.scene or shared / DEFAULT_SCENE
    scene = load_scene(path)
    camera = default_camera(scene, args.width, args.height, distance_scale=args.distance)
    settings = RenderSettings(background=(1.0, 1.0, 1.0))
    mesh = shapes(scene, camera)
    lines = [f"# Splats composited into a mesh render ({path.name}, {args.width}x{args.height})", "",
             describe(probe_machine()), ""]
    with Renderer() as renderer:
        image = MeshRenderer(renderer.ctx).render(mesh, camera, background=(1.0, 1.0, 1.0))
        z, face = meshes.ray_depth(mesh, camera)
        hit = face >= 0
        rel = np.abs(image.depth[hit] / z[hit] - 1.0)
        mismatch = int((np.isfinite(image.depth) != hit).sum())
        lines += ["Mesh depth against ray casting: "
                  f"{hit.sum()} pixels on the mesh, {mismatch} covered differently, "
                  f"largest relative depth error {rel.max():.1e}.", ""]
        under = image.under()
        # (2) the plane closed form
        view = View.of(camera, settings, scene)
        means, cam = pm.anchored(scene.means, view.anchor, view.camera, np.float64)
        zs = pm.to_camera(means, cam)[:, 2]
        z0 = float(np.median(zs[zs > view.near]))
        colour = np.array([0.3, 0.55, 0.8], np.float32)
        h, w = args.height, args.width
        plane = UnderImage(np.full((h, w, 3), colour, np.float32), np.ones((h, w), np.float32),
                           np.full((h, w), z0, np.float32), DepthKind.Z, Path("plane"))
        front = hide(scene, zs >= z0)        # the same scene (anchor, near plane) without them
        subset_settings = RenderSettings(background=tuple(colour))
        lines += [f"Plane at view z {z0:.4g} (the splats' median) against the splats in front of it "
                  "over the plane's colour:", "",
                  "| renderer | PSNR dB | max abs | > 1/255 % |", "|---|---:|---:|---:|"]
        for kind in (RendererKind.REFERENCE, RendererKind.TILE, RendererKind.QUAD):
            if kind is RendererKind.REFERENCE:
                got = render_reference_layers(scene, camera, settings, layers=LAYERS, under=plane)
                want = render_reference_layers(front, camera, subset_settings, layers=LAYERS)
            else:
                got = renderer.render_layers(scene, camera, settings, kind, layers=LAYERS, under=plane)
                want = renderer.render_layers(front, camera, subset_settings, kind, layers=LAYERS)
            lines.append(errors_row(kind.value, got.rgba, want.rgba))
        # (3) the box against the reference
        ref = render_reference_layers(scene, camera, settings, layers=LAYERS, under=under)
        lines += ["", "The box and floor composite against the reference's:", "",
                  "| renderer | PSNR dB | max abs | > 1/255 % |", "|---|---:|---:|---:|"]
        quad = None
        for kind in (RendererKind.TILE, RendererKind.QUAD):
            got = renderer.render_layers(scene, camera, settings, kind, layers=LAYERS, under=under)
            quad = got if kind is RendererKind.QUAD else quad
            lines.append(errors_row(kind.value, got.rgba, ref.rgba))
        splats = renderer.render(scene, camera, settings)
    text = "\n".join(lines) + "\n"
    print(text)
    if args.out is not None:
        args.out.write_text(text)
        print(f"wrote {args.out}")
    if args.picture is not None:
        gap = np.full((h + 24, 6, 3), 1.0, np.float32)
        row = np.concatenate([labelled(image.rgb, "mesh (splatgl.renderers.mesh)"), gap,
                              labelled(splats, "splats"), gap,
                              labelled(quad.rgba, "--under mesh.exr")], axis=1)
        write_image(args.picture, np.concatenate([row, np.ones(row.shape[:2] + (1,), np.float32)], -1))
        print(f"wrote {args.picture}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
