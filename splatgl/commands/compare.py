"""``splatgl compare``: a renderer, or an image made by any other program, against the per-tile
reference from the same camera; ``--explain`` says which approximation accounts for the difference."""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

from ..renderers.registry import entry, names as renderer_names, own_settings
from ..imagefiles.pictures import heatmap, side_by_side
from ..imagefiles.image_formats import image_format, suffix_list
from ..imagefiles.images import write_image
from ..progress import default_progress
from ..errors import SplatglError
from ..measure.evaluation.explain import candidates, explain
from ..measure.evaluation.metrics import check_ssim_size, depth_errors, image_errors
from ..measure.evaluation.their_image import ALPHA_CONVENTIONS, match_to_reference, read_their_image
from ..api import Renderer
from ..scene.settings import Order, RendererKind
from ._common import (add_camera_arguments, add_scene_arguments, add_settings_arguments,
                      check_convention, check_size, inputs_from_args, positive_float, size_origin)
from ._json_output import add_json_argument, check_json_target, emit_json, json_to_stdout
from ._outputs import add_force_argument, output_files

NAME = "compare"
ORDER = 30
HELP = "compare the quad path, the tile renderer or any image with the per-tile reference"
DESCRIPTION = """Render one view with two renderers, or read an image another program made from
the same camera, and print how far apart they are.

By default the quad path (global depth sort, instanced quads) is compared with the NumPy
per-tile reference rasterizer (3DGS rules).  Metrics are on RGB with the background
composited: PSNR (peak 1), SSIM, mean and max absolute error, and the share of pixels whose
largest channel error exceeds 1/255 and 4/255.

--image THEIRS scores a PNG, EXR, WebP, JPEG or TIFF (8/16-bit or float) against the reference
instead.  Its size must be the camera's (an image a few pixels off, transposed or upside down is
refused with a message that says so; --flip-y/--mirror-x turn it), an alpha channel is read as
premultiplied, straight or already composited (--alpha; auto takes the closest and says so),
and without one the image must show --background where the reference is empty.

--explain re-renders the reference with each approximation real viewers make (--emulate's
knobs, the per-pixel order, gsplat's rules) and reports which, alone and combined, bring it
closest to the image, with the dB each accounts for (docs/fidelity.md).

examples:
  splatgl compare scene.ply
  splatgl compare scene.ply --camera cameras.json --camera-index 2 --json
  splatgl compare scene.ply --camera cam.json --image theirs.png --explain
  splatgl compare scene.ply --extent fast --explain        (the quad path's fast extent)
  splatgl compare scene.ply --emulate sort=bucket16 --sort bucket16
  splatgl compare scene.ply --side-by-side both.png --heatmap err.png --heatmap-scale 0.01"""


def add_arguments(p: argparse.ArgumentParser) -> None:
    add_scene_arguments(p)
    p.add_argument("--renderer", choices=renderer_names(), default=None,
                   help="the renderer under test (default quad; not with --image, where the "
                        "image is under test)")
    p.add_argument("--against", choices=renderer_names(), default="reference",
                   help="the renderer taken as truth (default reference)")
    g = p.add_argument_group("another program's image")
    g.add_argument("--image", type=Path, default=None, metavar="FILE",
                   help="score this image (made from the same camera) instead of --renderer")
    g.add_argument("--alpha", choices=ALPHA_CONVENTIONS, default="auto",
                   help="how --image's alpha channel is read: straight (colour not multiplied "
                        "by alpha), premultiplied, composited (the background already in the "
                        "colour), or auto: the closest to the reference, reported (default)")
    g.add_argument("--flip-y", action="store_true", help="score --image turned upside down")
    g.add_argument("--mirror-x", action="store_true", help="score --image mirrored left to right")
    p.add_argument("--explain", action="store_true",
                   help="report which of the approximations real viewers make (the --emulate "
                        "knobs, the per-pixel order, gsplat's rules), alone and combined, bring "
                        "the reference closest to the image under test, with the dB each accounts "
                        "for (one reference render per knob; needs --against reference)")
    add_json_argument(p, "the figures (one object)")
    p.add_argument("--side-by-side", type=Path, default=None, metavar="FILE",
                   help=f"write both renders next to each other ({suffix_list()})")
    p.add_argument("--heatmap", type=Path, default=None, metavar="FILE",
                   help="write a heat map of the per-pixel error with its colour scale")
    p.add_argument("--heatmap-scale", type=positive_float, default=4.0 / 255.0, metavar="ERR",
                   help="error shown at the top of the heat map's scale (default 4/255)")
    add_force_argument(p)
    add_camera_arguments(p)
    add_settings_arguments(p)


def _check_options(args: argparse.Namespace) -> tuple[RendererKind, ...]:
    """Everything checkable before loading or rendering; returns the kinds that render."""
    against = RendererKind(args.against)
    if args.image is not None and args.renderer is not None:
        raise SplatglError(f"--renderer {args.renderer}: with --image the image is under test, "
                           "not a renderer (--against picks what it is measured against)")
    kinds = ((against,) if args.image is not None
             else (RendererKind(args.renderer or RendererKind.QUAD.value), against))
    check_convention(args, *kinds)
    if args.order == Order.PER_PIXEL.value and RendererKind.QUAD in kinds:
        raise SplatglError("--order per-pixel: the quad path has none (docs/fidelity.md); compare "
                           "--renderer tile or reference with the reference")
    if args.explain and against is not RendererKind.REFERENCE:
        raise SplatglError("--explain re-renders the NumPy reference: it needs --against reference")
    if args.image is None and (args.flip_y or args.mirror_x or args.alpha != "auto"):
        raise SplatglError("--flip-y, --mirror-x and --alpha apply to --image")
    files = _files(args)  # not SCENE, --camera, --image...; an existing file only with --force
    for option, path in files.targets.items():
        image_format(path, option)  # before rendering (x.bmp, or no suffix at all)
    check_json_target(args, {"--side-by-side": args.side_by_side, "--heatmap": args.heatmap})
    if args.stereo is not None:
        raise SplatglError("--stereo renders with splatgl render or view; compare measures one view")
    return kinds


def _files(args: argparse.Namespace):
    """The pictures compare writes (checked against its inputs and --force)."""
    return output_files(args, {"--side-by-side": args.side_by_side, "--heatmap": args.heatmap})


def run(args: argparse.Namespace) -> int:
    kinds = _check_options(args)
    files = _files(args)
    scene, settings, camera = inputs_from_args(args)
    check_ssim_size(camera.width, camera.height, size_origin(args))
    theirs = read_their_image(args.image, camera.width, camera.height) if args.image else None
    progress = default_progress()
    outputs, seconds = [], []
    with Renderer() as renderer:
        for kind in kinds:
            check_size(args, camera, kind, renderer.ctx)
        for kind in kinds:
            side = own_settings(settings, kind)   # e.g. the knobs are the reference's
            if entry(kind).warms_up:
                renderer.render(scene, camera, side, kind, progress)  # warm-up: compile, upload
            t0 = time.perf_counter()
            outputs.append(renderer.render_layers(scene, camera, side, kind, progress))
            seconds.append(time.perf_counter() - t0)
    truth = outputs[-1]
    names = tuple(k.value for k in kinds)
    notes: tuple[str, ...] = ()
    result_extra: dict = {}
    if theirs is not None:
        matched = match_to_reference(theirs, truth.rgba[..., :3], truth.alpha, settings.background,
                                     args.alpha, args.flip_y, args.mirror_x)
        got = np.concatenate([matched.rgb, truth.alpha[..., None]], -1)  # alpha: see below
        names = (args.image.name, names[0])
        notes = matched.notes
        result_extra = {"image": str(args.image), "alpha_convention": matched.convention,
                        "flipped_y": matched.flipped, "mirrored_x": matched.mirrored}
        if matched.alpha is not None:
            result_extra["image_alpha_max_abs"] = float(np.abs(matched.alpha - truth.alpha).max())
        depth = {}
    else:
        got = outputs[0].rgba
        depth = depth_errors(outputs[0], truth)
    errors = image_errors(got, truth.rgba)
    explanation = None
    if args.explain:
        explanation = _explain(scene, camera, settings, got[..., :3])
    with files:
        if args.side_by_side is not None:
            write_image(files.temp("--side-by-side"), side_by_side(got, truth.rgba, names))
        if args.heatmap is not None:
            write_image(files.temp("--heatmap"), heatmap(got, truth.rgba, args.heatmap_scale))
    result = {
        "scene": str(args.scene) if args.scene else "demo", "splats": scene.count,
        "width": camera.width, "height": camera.height, "renderer": names[0], "against": names[-1],
        **result_extra, **errors.as_dict(), **depth,
        "seconds": dict(zip(names[-len(seconds):], seconds)),
        "emulate": settings.emulation.label(), "order": settings.order.value,
    }
    if explanation is not None:
        result["explain"] = explanation.as_dict()
    if json_to_stdout(args):
        emit_json(args, result)
        return 0
    _print_report(result, errors, depth, names, seconds, notes, scene.count, camera)
    if args.side_by_side is not None:
        print(f"wrote {args.side_by_side} (side by side: {names[0]} | {names[-1]})")
    if args.heatmap is not None:
        print(f"wrote {args.heatmap} (error heatmap, top of its scale at |err| {args.heatmap_scale:.3g})")
    if explanation is not None:
        print("\n".join(explanation.lines()))
    if args.json is not None:
        emit_json(args, result)
    return 0


def _explain(scene, camera, settings, target: np.ndarray):
    """Rank the reference's knobs against ``target`` (the image under test, (H, W, 3))."""
    from ..reference import render_reference

    progress = default_progress()

    def render(s):
        return render_reference(scene, camera, s, np.float32, compat=s.convention).color

    return explain(render, target, settings, candidates(scene, camera, settings), progress)


def _print_report(result, errors, depth, names, seconds, notes, count, camera) -> None:
    psnr = "inf" if errors.psnr == float("inf") else f"{errors.psnr:.2f} dB"
    against = names[-1] if result["emulate"] == "reference" else f"{names[-1]} ({result['emulate']})"
    print(f"{result['scene']}: {count} splats, {camera.width}x{camera.height}, "
          f"{names[0]} against {against}")
    for note in notes:
        print(f"  {note}")
    print(f"  PSNR       {psnr}")
    print(f"  SSIM       {errors.ssim:.6f}")
    print(f"  mean |err| {errors.mean_abs:.3e}")
    print(f"  max |err|  {errors.max_abs:.3e}")
    print(f"  > 1/255    {errors.off_1 * 100:.3f} % of pixels")
    print(f"  > 4/255    {errors.off_4 * 100:.3f} % of pixels")
    if "image_alpha_max_abs" in result:
        print(f"  alpha      max |err| {result['image_alpha_max_abs']:.3e} (the image's alpha channel)")
    if depth:
        print(f"  alpha      max |err| {depth['alpha_max_abs']:.3e}")
        print(f"  depth D    max |err| {depth['depth_max_abs']:.3e} = {depth['depth_max_rel'] * 100:.3f} % of "
              f"the farthest expected depth {depth['depth_scale']:.4g}")
    print("  time       " + ", ".join(f"{n} {s * 1e3:.1f} ms" for n, s in zip(names[-len(seconds):], seconds))
          + " (colour and depth)")
    sys.stdout.flush()
