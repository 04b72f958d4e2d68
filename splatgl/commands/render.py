"""``splatgl render``: render one view to an image file."""

from __future__ import annotations

import argparse
from pathlib import Path

from ..errors import SplatglError
from ..imagefiles.frame_targets import FrameTarget
from ..imagefiles.image_formats import (BIT_DEPTHS, IMAGE_FORMATS, PICTURE_FORMATS, image_format,
                                        picture_format, suffix_list)
from ..imagefiles.images import write_image
from ..imagefiles.layer_files import check_exact_ids, picture_path, write_layers
from ..output.layers import BASE, Layer, RenderOutput
from ..progress import default_progress
from ..imagefiles.pictures import depth_preview
from ..api import Renderer, gl_renderer_name
from ..lod.frames import LodFrames, render_lod
from ..lod.budget import format_size
from ..lod.io import framed_leaves, read_lod
from ..lod.stream_frames import StreamFrames
from ..scene.settings import RendererKind
from ._renderer_auto import AUTO, auto_lines, choose_renderer
from ._common import (add_camera_arguments, add_scene_arguments, add_settings_arguments,
                      camera_from_args, check_convention, check_size, check_stereo_layout,
                      format_timings, inputs_from_args, settings_from_args)
from ._layers import add_layer_arguments, layer_files, under_from_args
from ._memory import (STREAM_HELP, add_level_argument, add_memory_argument, memory_given,
                      render_one_streamed, stream_inputs, stream_level, stream_renderer)
from ._outputs import add_force_argument, output_files
from ._render_path import (add_path_arguments, lod_settings_from_args, refuse_path_only_options,
                           run_path)
from ..renderers.registry import entry, names as renderer_names
from ..renderers.stereo import StereoLayout, combine, eye_cameras

NAME = "render"
ORDER = 10
HELP = "render a scene (default: the bundled demo) to PNG, TIFF or EXR"
DESCRIPTION = """Render one view of a Gaussian-splat scene headlessly (EGL, or OSMesa).

The output format follows the extension: .png and .tif/.tiff get RGB with the background
composited (8-bit, or 16-bit with --bit-depth 16); .exr gets float R, G, B, A and Z, where Z
is the expected depth D / A (camera-space z, world units; a fisheye's or panorama's distance;
0 where nothing was drawn) and D = sum z alpha T is accumulated with the colour's weights in
the same pass.  --layers asks for more: the median depth, normals, the number of splats per
pixel and the index of the splat with the largest weight (docs/layers.md); --under composites
the splats into a render of opaque geometry by depth.

examples:
  splatgl render -o demo.png
  splatgl render scene.ply --camera cameras.json --camera-index 3 -o view.exr
  splatgl render scene.ply --width 1920 --height 1080 --background 1,1,1 -o white.png
  splatgl render scene.ply -o view.png --depth-png depth.png
  splatgl render scene.ply -o view.exr --layers colour,alpha,depth,median-depth,normal,count,top-id
  splatgl render scene.ply -o view.png --layers normal,count      (view_normal.png, view_count.png)
  splatgl render scene.ply --camera cam.json --under mesh.exr -o composite.png
  splatgl render scene.ply --path orbit:120 -o orbit.mp4
  splatgl render scene.ply --path dataset/sparse/0 --select 0:100:5 -o frames/%05d.png"""


def add_arguments(p: argparse.ArgumentParser) -> None:
    add_scene_arguments(p)
    p.add_argument("-o", "--output", required=True,  # text: with --path a trailing / matters
                   help=f"output image ({suffix_list(IMAGE_FORMATS, ', ')}); with --path a folder, a "
                        "pattern such as frames/%%05d.png, or a video (.mp4)")
    p.add_argument("--bit-depth", type=int, choices=BIT_DEPTHS, default=None,
                   help="bits per channel of PNG/TIFF output (default 8); refused for an EXR "
                        "(float32) and for a video's frames above 8")
    p.add_argument("--renderer", choices=[AUTO] + renderer_names(), default=AUTO,
                   help="auto (default) = cpu on a machine without a GPU where it can draw the "
                        "request and its compiled kernels are ready (no option only the quad path "
                        "reads), else quad; quad = the OpenGL quad path; tile = the per-tile "
                        "compute-shader renderer; reference = the NumPy per-tile reference (slow); "
                        "cpu = the reference's algorithm compiled for the CPU, no OpenGL (needs "
                        "the fast extra; 3DGS colour, alpha and depth; about 3x faster than the "
                        "quad path on software OpenGL). --timings says which ran")
    p.add_argument("--depth-png", type=Path, default=None, metavar="FILE",
                   help="also write a colourised preview of the expected depth with a scale bar")
    add_force_argument(p)
    p.add_argument("--timings", action="store_true",
                   help="print the frame's stage times (ms) and counts (splats drawn, keys sorted)")
    p.add_argument("--lod-threshold", type=float, default=None, metavar="PX",
                   help="level of detail (SCENE from 'splatgl lod'): draw the coarsest nodes whose "
                        "bounding sphere projects to at most PX pixels (e.g. 1)")
    p.add_argument("--lod-budget", type=int, default=None, metavar="N",
                   help="level of detail: the finest cut of at most N nodes per view (with "
                        "--lod-threshold, never finer than PX)")
    p.add_argument("--lod-blend", type=float, default=None, metavar="RATIO",
                   help="level of detail: nodes projecting to between PX and RATIO x PX pixels are "
                        "drawn as a blend of themselves and their children (opacity weights), so "
                        "a path's frames change smoothly instead of popping; 1 for no blending "
                        "(default 2)")
    add_memory_argument(p, STREAM_HELP)
    add_level_argument(p)
    add_camera_arguments(p)
    add_settings_arguments(p)
    add_layer_arguments(p)
    add_path_arguments(p)


def run(args: argparse.Namespace) -> int:
    check_stereo_layout(args)
    args.bit_depth = bit_depth_from_args(args)
    if args.path is not None:
        return run_path(args)
    args.output = Path(args.output)
    refuse_path_only_options(args)
    kind = RendererKind(args.renderer if args.renderer != AUTO else "quad")   # auto: below
    check_convention(args, kind)
    if args.depth_png is not None:
        picture_format(args.depth_png, "--depth-png")
    plan = layer_files(args, None)           # --layers checked before any work
    stereo = StereoLayout(args.stereo_layout) if args.stereo is not None else None
    if stereo is not None and args.under is not None:
        raise SplatglError("--under composites one camera's view into its geometry; not with --stereo")
    eyes_out = ({"left": _eye_name(args.output, "left"), "right": _eye_name(args.output, "right")}
                if stereo is StereoLayout.SEPARATE else {"": args.output})
    targets: dict[str, Path] = {}          # every file written, by its OutputFiles name
    for eye, path in eyes_out.items():
        what = f"-o ({eye} eye)" if eye else "-o"
        targets[what] = path
        targets.update({f"{what} ({layer.value})": picture_path(path, layer) for layer in plan.pictures(path)})
    depth_names = ({eye: _eye_name(args.depth_png, eye) for eye in eyes_out} if stereo is StereoLayout.SEPARATE
                   else {"": args.depth_png}) if args.depth_png is not None else {}
    targets.update({f"--depth-png ({eye} eye)" if eye else "--depth-png": path
                    for eye, path in depth_names.items()})
    outputs = output_files(args, targets)  # refuses one file named twice, an input, an
    #                                        existing file without --force
    keys = {path: name for name, path in targets.items()}
    fmt = image_format(args.output, "-o")  # before rendering (x.bmp, or no suffix at all)
    under = under_from_args(args)
    memory = memory_given(args)
    stream_level(args)         # --lod-level: with --memory and a Streamed SOG or LCC
    if memory is not None:     # streamed: the file is never read whole
        cut = lod_settings_from_args(args)   # a .lod.ply, the quad path
        if stereo is not None:
            raise SplatglError(StreamFrames.stereo_refusal)
        settings = settings_from_args(args)
        scene, camera = stream_inputs(args, settings)
    elif lod_given(args):      # an in-memory level of detail: the file read once, as a tree
        cut = lod_settings_from_args(args)   # its checks (a .lod.ply) before reading it
        if stereo is not None:
            raise SplatglError(LodFrames.stereo_refusal)
        settings = settings_from_args(args)
        camera_from_args(args, None, settings)   # the camera file and options checked first
        tree = read_lod(args.scene, progress=default_progress())
        scene = framed_leaves(tree, args.scene)
        camera = camera_from_args(args, scene, settings)   # the leaves frame it, as load_scene's
    else:
        scene, settings, camera = inputs_from_args(args)
    if args.renderer == AUTO and memory is None and not lod_given(args):
        kind = choose_renderer(args, scene, settings, camera, plan.render_layers(args.output)
                               | ({Layer.DEPTH} if args.depth_png is not None else set()), under)
    elif memory is not None:        # streamed: auto as above, the quad path or the cpu renderer
        kind = stream_renderer(args, settings, scene, camera, plan.render_layers(args.output)
                               | ({Layer.DEPTH} if args.depth_png is not None else set()), under)
    elif args.renderer == AUTO:     # an in-memory level of detail: the quad path's
        args.renderer = RendererKind.QUAD.value
    files = layer_files(args, camera)
    check_exact_ids(files, args.output, scene.count)
    # what the file holds (EXR: the depth layer as Z), and the depth the preview needs
    layers = files.render_layers(args.output) | ({Layer.DEPTH} if args.depth_png is not None else set())
    lod = lod_given(args)
    times = None
    if memory is not None:
        out, times, gl_name = render_one_streamed(args, camera, settings, cut, memory, layers,
                                                  under, scene)
        eyes = [out]
        kind_text = f"{kind.value}, level of detail streamed under {format_size(memory)}"
    elif lod:
        out, times, gl_name = render_lod(tree, camera, settings, cut, layers, under)
        del tree
        eyes = [out]
        kind_text = f"{kind.value}, level of detail"
    else:
        cameras = list(eye_cameras(camera, args.stereo)) if stereo is not None else [camera]
        eyes, times, gl_name = _render(args, scene, settings, cameras, kind, layers, under)
        kind_text = kind.value
    if stereo is not StereoLayout.SEPARATE:
        eyes = [combine(eyes[0], eyes[1], stereo) if stereo is not None else eyes[0]]
    with outputs:
        for eye, out in zip(eyes_out, eyes):
            write_layers(eyes_out[eye], out, files, args.bit_depth, lambda p: outputs.temp(keys[p]),
                         write_image)
            if eye in depth_names:
                write_image(outputs.temp(keys[depth_names[eye]]),
                            depth_preview(out.expected_depth(), out.alpha))
    for path in depth_names.values():
        print(f"wrote {path} (expected depth)")
    cut = getattr(times, "cut_nodes", None)   # a level of detail draws its cut, not the scene
    splats = f"{scene.count} splats" if cut is None else f"a {cut:,}-splat cut of {scene.count:,}"
    for eye, path in eyes_out.items():
        height, width = eyes[0].rgba.shape[:2]
        shown = [layer.value for layer in files.render_layers(path) if fmt.is_float] if plan.named else []
        extra = f", layers {', '.join(sorted(shown))}" if shown else ""
        print(f"wrote {path} ({width}x{height}, {splats}, {kind_text}{extra})")
        for layer in plan.pictures(path):
            print(f"wrote {picture_path(path, layer)} ({layer.value})")
    if memory is not None and getattr(times, "capped", None):   # said once, here
        print(times.capped)
    _print_timings(args, gl_name, times, settings)
    return 0


def bit_depth_from_args(args: argparse.Namespace) -> int:
    """``--bit-depth`` (default 8) where the output takes it: a PNG or TIFF (8 or 16), a
    video's frames (8); an EXR (float32 channels) or a 16-bit video is one line, never a file
    written at another depth than asked."""
    if args.bit_depth is None:
        return 8
    target = FrameTarget.parse(args.output, args.format) if args.path is not None else None
    if target is not None and target.is_video:
        depths, what = (8,), "is a video, whose frames are 8-bit"
    else:   # a float format (EXR) has no depth to choose
        fmt = target.image_format if target is not None else image_format(args.output, "-o")
        name = fmt.name.upper()
        depths = fmt.bit_depths
        what = (f"is an {name} image" if target is None else f"gets {name} frames") + \
            ", whose channels are float32"
    if args.bit_depth not in depths:
        raise SplatglError(f"--bit-depth {args.bit_depth}: -o {args.output} {what}; "
                           f"--bit-depth applies to {suffix_list(PICTURE_FORMATS)} output "
                           f"({' or '.join(map(str, BIT_DEPTHS))} bits per channel)")
    return args.bit_depth


def lod_given(args: argparse.Namespace) -> bool:
    """Whether a --lod-* option asks for a level-of-detail cut (drawn by the quad path)."""
    return any(v is not None for v in (args.lod_threshold, args.lod_budget, args.lod_blend))


def _eye_name(path: Path, eye: str) -> Path:
    """``OUT_left.EXT`` / ``OUT_right.EXT``: one eye's file of --stereo-layout separate."""
    return path.with_name(f"{path.stem}_{eye}{path.suffix}")


def _print_timings(args: argparse.Namespace, gl_name: str, times, settings) -> None:
    """With --timings: the GL renderer (which device ran the frame), what each ``auto`` option
    chose, and the stage times."""
    if args.timings:
        print(f"GL renderer: {gl_name}")
        for line in auto_lines(args, settings, gl_name):
            print(line)
        if times is not None:
            print(f"timings: {format_timings(times)}")


def _render(args, scene, settings, cameras, kind, layers, under=None):
    """(a RenderOutput per camera, the renderer's last_times or None, the GL renderer's name):
    one context for all; ``under``: geometry to composite into."""
    progress = default_progress()
    outs = []
    gl = entry(kind).gl        # no OpenGL context for a renderer that draws without one
    with Renderer() as renderer:
        for camera in cameras:
            check_size(args, camera, kind, renderer.ctx if gl else None)
            if layers != BASE or under is not None:
                outs.append(renderer.render_layers(scene, camera, settings, kind, progress, layers,
                                                   under))
            else:
                outs.append(RenderOutput(renderer.render(scene, camera, settings, kind, progress), None))
        times = renderer.renderer_for(scene, settings, kind).last_times
        gl_name = gl_renderer_name(kind, renderer.ctx if gl else None)
    return outs, times, gl_name
