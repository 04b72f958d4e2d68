"""Argument groups shared by the commands that render (render, compare, view, bench)."""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

from ..cameras.camera import Camera
from ..cameras import registry
from ..cameras.camera_files import load_camera
from ..errors import SplatglError
from ..formats import load_scene, scene_source
from ..cameras.orthographic import Orthographic
from ..gl.device_class import AUTO, resolve_sort
from ..gl.limits import MAX_IMAGE_SIDE
from ..gl.transfers import TransferCounts
from ..api import default_camera, default_settings
from ..scene.splats import Scene
from ..constants import EARLY_STOP_MIN_OVERDRAW, EARLY_STOP_MIN_QUAD_FRAGMENTS
from ..scene.settings import (Convention, EarlyStop, GpuStorage, Precision, Preprocess, QuadExtent,
                              RendererKind, RenderSettings, SortKey)
from ..renderers.registry import check_image_size, check_settings
from ._fidelity_args import add_fidelity_arguments, fidelity_fields
from ..renderers.stereo import StereoLayout
from ..scene.transform import parse_transform
from ._spz_axes import add_spz_axes_argument
from ._outputs import add_force_argument  # noqa: F401  (re-exported: one --force)
from ..cameras.up import UP_CHOICES, resolve_up


def demo_scene_path() -> Path:
    """The bundled demo scene: inside the installed package, or the repository's scenes/."""
    here = Path(__file__).resolve().parent.parent
    for candidate in (here / "scenes" / "demo.ply", here.parent / "scenes" / "demo.ply"):
        if candidate.is_file():
            return candidate
    raise SplatglError(f"bundled demo scene not found next to {here} (broken installation?)")


def parse_rgb(text: str) -> tuple[float, float, float]:
    """``R,G,B``: three finite, non-negative numbers (above 1 is kept as such in EXR output)."""
    try:
        parts = [float(p) for p in text.split(",")]
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected R,G,B numbers, got {text!r}") from None
    if len(parts) != 3:
        raise argparse.ArgumentTypeError(f"expected 3 comma-separated values, got {text!r}")
    if not all(math.isfinite(v) and v >= 0.0 for v in parts):
        raise argparse.ArgumentTypeError(f"each of R,G,B must be a finite number >= 0, got {text!r}")
    return tuple(parts)


def _argument_type(convert, ok, kind: str, requirement: str):
    """An argparse type: ``convert(text)`` (else "expected {kind}"), kept only where ``ok``."""
    def parse(text: str):
        try:
            value = convert(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected {kind}, got {text!r}") from None
        if not ok(value):
            shown = value if isinstance(value, int) else repr(text)
            raise argparse.ArgumentTypeError(f"must be {requirement}, got {shown}")
        return value
    return parse


#: An integer >= 1.
positive_int = _argument_type(int, lambda v: v >= 1, "a whole number", "at least 1")
#: An integer >= 0.
non_negative_int = _argument_type(int, lambda v: v >= 0, "a whole number", "0 or more")
#: A finite number > 0 (not nan, not inf).
positive_float = _argument_type(float, lambda v: math.isfinite(v) and v > 0.0, "a number",
                                "a finite number > 0")


def add_scene_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("scene", nargs="?", type=Path, default=None,
                   help="scene file (.ply, .splat, ...); default: the bundled demo scene")
    p.add_argument("--drop-invalid", action="store_true",
                   help="drop rows with NaN/Inf values or zero quaternions (with a warning that "
                        "counts them) instead of rejecting the file")
    add_spz_axes_argument(p)


def add_camera_arguments(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group("camera")
    g.add_argument("--camera", type=Path, default=None,
                   help="camera file: splatgl single-camera JSON, or a 3DGS cameras.json "
                        "(default: a view that frames the scene)")
    g.add_argument("--camera-index", type=non_negative_int, default=None, metavar="N",
                   help="which camera of a cameras.json list, counting from 0 (default 0)")
    g.add_argument("--width", type=positive_int, default=None,
                   help=f"image width in pixels, at most {MAX_IMAGE_SIDE} and what the OpenGL "
                        "driver allows (default 1280, 2 x --height for an equirectangular "
                        "panorama, or the camera file's; with a camera file its intrinsics are "
                        "scaled, and --width alone keeps the file's aspect)")
    g.add_argument("--height", type=positive_int, default=None,
                   help="image height in pixels (default 720; with a camera file, giving both "
                        "--width and --height must keep its aspect unless --projection or --fov "
                        "replaces its intrinsics)")
    g.add_argument("--fov", type=positive_float, default=None,
                   help="vertical field of view, degrees (default 50; fisheye: see "
                        "--projection); with --camera it replaces the file's intrinsics, keeping "
                        "its pose. Not for orthographic or equirectangular cameras")
    g.add_argument("--orthographic", action="store_true",
                   help="make the default camera orthographic, zoomed to frame the scene "
                        "(not with --camera: see --projection)")
    g.add_argument("--projection", choices=registry.names(), default=None,
                   help="camera model: perspective (default), orthographic, fisheye "
                        "(equidistant; --fov is the image circle's field of view, default 180, up "
                        "to 360) or equirectangular (a full 360 x 180 degree panorama, usually "
                        "--width 2 x --height, the default).  With --camera, the file's pose is "
                        "kept and the size is --width x --height (default: the file's; a "
                        "panorama 2:1 at the file's height)")
    g.add_argument("--stereo", type=positive_float, default=None, metavar="IPD",
                   help="render a stereo pair with this interpupillary distance (world units); "
                        "equirectangular cameras render omni-directional stereo")
    g.add_argument("--stereo-layout", choices=[m.value for m in StereoLayout], default=None,
                   help="with --stereo, where the two eyes go: side-by-side (left | right, "
                        "default), top-bottom (left above right, the 360-video convention), or "
                        "separate files OUT_left.EXT and OUT_right.EXT")
    g.add_argument("--distance", type=positive_float, default=None, metavar="SCALE",
                   help="default camera distance as a multiple of the framing distance "
                        "(default 1; 0.5 is twice as close)")
    g.add_argument("--up", choices=UP_CHOICES, default=None,
                   help="world axis that points up in the default camera's image. Default: the "
                        "average up of the training cameras when the scene comes with them (the "
                        "--camera cameras.json, or a cameras.json beside the scene or up to three "
                        "folders above it, as 3DGS training writes it); otherwise -y, the "
                        "COLMAP convention most trained scenes follow")


def add_settings_arguments(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group("rendering")
    g.add_argument("--background", type=parse_rgb, default=(0.0, 0.0, 0.0), metavar="R,G,B",
                   help="background colour composited behind the splats, 0-1 (default 0,0,0; "
                        "values above 1 are kept in EXR output and clip to white in PNG/TIFF)")
    g.add_argument("--precision", choices=[m.value for m in Precision], default="rgba32f",
                   help="blend target of the quad path (default rgba32f)")
    g.add_argument("--extent", choices=[m.value for m in QuadExtent], default="ellipse",
                   help="quad size: 'ellipse' = opacity-aware ellipse axes (default), 'square' = "
                        "the reference's 3-sigma square, 'fast' = the web viewers' approximation: "
                        "a fixed 2.83 sigma (2 sqrt 2) along the ellipse axes whatever the "
                        "opacity, the fragment evaluating the Gaussian in those axes (quicker, "
                        "less exact: docs/fidelity.md)")
    g.add_argument("--near", type=positive_float, default=None,
                   help="near-plane distance in world units (default: min(0.2, 1%% of the "
                        "scene's robust radius))")
    g.add_argument("--antialias", action=argparse.BooleanOptionalAction, default=None,
                   help="apply the reference's antialiasing opacity compensation (default: on "
                        "for scenes whose file says they were trained with antialiasing, e.g. "
                        "SPZ's antialiased flag or a 'SplatRenderMode: mip' PLY comment, with "
                        "a message; off otherwise)")
    g.add_argument("--sh-degree", type=int, default=None, choices=range(4),
                   help="cap the SH degree evaluated (default: the scene's)")
    g.add_argument("--preprocess", choices=[m.value for m in Preprocess], default=None,
                   help="where the quad path's per-splat math runs: 'vertex' shader (per corner) "
                        "or a 'compute' pre-pass (per splat); default: what the benchmark chose")
    g.add_argument("--sort", choices=[AUTO] + [m.value for m in SortKey], default=AUTO,
                   help="depth sort: 'auto' (default) 'gpu' on a hardware GPU and 'exact' on a "
                        "software rasteriser such as llvmpipe (--timings says which ran); "
                        "'exact' 32-bit keys on the CPU; 'gpu' the same "
                        "keys by a compute-shader radix sort, the order kept on the device (quad "
                        "path and tile renderer; identical images; faster on real GPUs, slower on "
                        "llvmpipe); or 'bucket16' 16-bit buckets (quad path, approximate)")
    g.add_argument("--convention", choices=[m.value for m in Convention], default="inria",
                   help="rules of the NumPy reference: 'inria' = the 3DGS rasterizer (default), "
                        "'gsplat' = per-axis opacity-aware extent up to 3.33 sigma, alpha clamp 0.999. "
                        "The quad and tile renderers follow the inria rules only, so 'gsplat' "
                        "needs --renderer reference (in compare: a reference on either side)")
    g.add_argument("--early-stop", choices=[m.value for m in EarlyStop], default=None,
                   help="quad path early termination: draw the sorted splats in batches, stop "
                        "shading pixels whose transmittance fell below 1e-4 and drop splats that "
                        "land only on such pixels. 'auto' (default): on a hardware GPU 'on' "
                        "(measured on one H100); on a software rasteriser it batches a view only "
                        "where its quads will rasterise at least %g fragments each and %g per "
                        "image pixel, where batching paid on llvmpipe; 'on' always, 'off' never "
                        "(docs/early-stop.md)" % (EARLY_STOP_MIN_QUAD_FRAGMENTS, EARLY_STOP_MIN_OVERDRAW))
    g.add_argument("--gpu-storage", choices=[m.value for m in GpuStorage], default="float32",
                   help="how the scene is stored on the GPU (quad and tile renderers), bytes per "
                        "splat at SH degree 0 / 3: 'float32' 64 / 244 (exact); 'half-sh' 64 / 154 "
                        "(SH coefficients 1.. as float16, colour error below 2e-4); 'compact' "
                        "32 / 122 (also opacity 16-bit, rotation 15 bits per component, scales "
                        "and base colour float16: PSNR >= 80 dB against float32 on every shared "
                        "real scene; docs/scale.md)")
    g.add_argument("--half-sh", dest="gpu_storage", action="store_const", const="half-sh",
                   help="the same as --gpu-storage half-sh (kept for older scripts)")
    g.add_argument("--transform", type=str, default=None, metavar="JSON",
                   help='place the scene in the world: inline JSON or a JSON file, e.g. '
                        '\'{"rotate_deg": [0, 90, 0], "translate": [0, 0, 1], "scale": 2}\' '
                        "(rotations about x, then y, then z; or \"rotation\": 3x3). SH is "
                        "evaluated in the scene's own frame")
    add_fidelity_arguments(g)


def load_scene_arg(args: argparse.Namespace) -> Scene:
    path = args.scene if args.scene is not None else demo_scene_path()
    return load_scene(path, drop_invalid=args.drop_invalid,
                      spz_axes=getattr(args, "spz_axes", None))


def antialias_from_args(args: argparse.Namespace) -> bool:
    """``--antialias`` / ``--no-antialias`` if given, else the scene file's default
    (:func:`splatgl.default_settings`: on where the file is tagged as trained with
    antialiasing), saying so on stderr.  Read from the file's header, before loading it."""
    if args.antialias is not None:
        return args.antialias
    path = getattr(args, "scene", None)
    source = scene_source(path) if path is not None else None
    antialias = default_settings(source, sort_key="exact").antialias   # no device asked
    if antialias:
        print(f"splatgl: {path}: {source.antialias_tag}: rendering with --antialias "
              "(--no-antialias turns it off)", file=sys.stderr)
    return antialias


def settings_from_args(args: argparse.Namespace) -> RenderSettings:
    model = parse_transform(args.transform) if args.transform else None
    optional = {"preprocess": args.preprocess} if args.preprocess else {}
    if getattr(args, "early_stop", None) is not None:
        optional["early_stop"] = EarlyStop(args.early_stop)
    return RenderSettings(background=args.background, precision=args.precision, extent=args.extent,
                          near=args.near, antialias=antialias_from_args(args),
                          sh_degree=args.sh_degree,
                          transform=model, sort_key=sort_from_args(args), gpu_storage=args.gpu_storage,
                          convention=args.convention, **optional, **fidelity_fields(args))


def sort_from_args(args: argparse.Namespace) -> SortKey:
    """``--sort``; ``auto`` by the device (:func:`splatgl.gl.device_class.resolve_sort`), and
    ``exact`` for a renderer that reads no sort (reference, cpu: nothing to ask the device)."""
    if args.sort == AUTO and getattr(args, "renderer", None) in (RendererKind.REFERENCE.value,
                                                                 RendererKind.CPU.value):
        return SortKey.EXACT
    return resolve_sort(args.sort)


def check_convention(args: argparse.Namespace, *kinds: RendererKind | str, **advice) -> None:
    """``--convention gsplat`` and ``--emulate`` need the NumPy reference among ``kinds``,
    ``--order per-pixel`` the reference or the tile renderer, and every option only some
    renderers read one that reads it (:func:`splatgl.renderers.registry.check_settings`),
    checked before any work."""
    check_settings(RenderSettings(convention=args.convention, **quad_fields(args),
                                  **fidelity_fields(args)), *kinds, **advice)


def quad_fields(args: argparse.Namespace) -> dict:
    """The RenderSettings fields of the options only some renderers read
    (:data:`splatgl.renderers.registry.OPTIONS`), where the command has them."""
    names = {"precision": "precision", "extent": "extent", "sort_key": "sort",
             "preprocess": "preprocess", "early_stop": "early_stop", "gpu_storage": "gpu_storage"}
    return {field: getattr(args, name) for field, name in names.items()
            if getattr(args, name, None) not in (None, AUTO)}   # auto: what the device draws best


def size_origin(args: argparse.Namespace) -> str:
    """Where the image size came from, for messages: the options, or the camera file's fields."""
    if args.width or args.height or args.camera is None:
        return "--width/--height: image"
    return f"{args.camera}: fields 'width', 'height': image"


def check_size(args: argparse.Namespace, camera: Camera, kind: RendererKind | str, ctx=None) -> None:
    """The image size against this machine's limits (:mod:`splatgl.gl.limits`), before allocating."""
    check_image_size(camera.width, camera.height, size_origin(args), kind, ctx,
                     getattr(args, "precision", None) or "rgba32f")


def projection_from_args(args: argparse.Namespace) -> str | None:
    """``--projection``, with ``--orthographic`` as its other spelling (never contradicting it)."""
    projection = getattr(args, "projection", None)
    if getattr(args, "orthographic", False):
        if projection not in (None, Orthographic.name):
            raise SplatglError(f"--orthographic contradicts --projection {projection} "
                               "(--orthographic is --projection orthographic); give one of them")
        projection = Orthographic.name
    return projection


def _file_camera(args: argparse.Namespace, projection: str | None,
                 orbit_up: bool = False) -> Camera:
    """``--camera`` adapted by --width/--height/--projection/--fov (:func:`splatgl.load_camera`);
    ``--up`` is refused beside it unless ``orbit_up`` (the viewer's orbit keeps it)."""
    if getattr(args, "orthographic", False):
        raise SplatglError(f"--orthographic zooms the default camera to frame the scene; "
                           f"{args.camera} brings its own camera (--projection orthographic keeps "
                           "its fx, fy as pixels per world unit)")
    if getattr(args, "distance", None) is not None:
        raise SplatglError(f"--distance places the default camera; {args.camera} brings its own pose")
    if getattr(args, "up", None) is not None and not orbit_up:
        raise SplatglError(f"--up {args.up} places the default camera and orbit paths; "
                           f"{args.camera} brings its own pose, which fixes which way is up")
    cam = load_camera(args.camera, args.camera_index or 0, width=args.width, height=args.height,
                      projection=projection, fov_degrees=args.fov)
    check_image_size(cam.width, cam.height, size_origin(args), RendererKind.REFERENCE)
    return cam


def default_size(args: argparse.Namespace, projection: str | None) -> tuple[int, int]:
    """The default camera's image size (:func:`splatgl.cameras.registry.default_size`: a
    panorama 2:1), checked with --fov before the scene is loaded."""
    width, height = registry.default_size(projection, args.width, args.height)
    check_image_size(width, height, size_origin(args), RendererKind.REFERENCE)
    registry.check_fov(projection, args.fov)
    return width, height


def check_stereo_layout(args: argparse.Namespace) -> None:
    """``--stereo-layout`` lays out ``--stereo``'s pair: refused without it (it was accepted and
    ignored); with it, ``args.stereo_layout`` is side-by-side unless given."""
    layout = getattr(args, "stereo_layout", None)
    if getattr(args, "stereo", None) is None:
        if layout is not None:
            raise SplatglError(f"--stereo-layout {layout} lays out a stereo pair: add --stereo "
                               "IPD, or leave --stereo-layout out")
    elif layout is None:
        args.stereo_layout = StereoLayout.SIDE_BY_SIDE.value


def camera_from_args(args: argparse.Namespace, scene: Scene | None,
                     settings: RenderSettings | None = None,
                     orbit_up: bool = False) -> Camera | None:
    """The camera the options describe (:func:`splatgl.load_camera` or
    :func:`splatgl.default_camera`); with ``scene`` None, only the checks that need no scene
    (done before loading one), returning the file's camera or None.  ``orbit_up``: the command
    orbits about ``--up`` (view), which a camera file then does not refuse."""
    if args.camera is None and args.camera_index is not None:
        raise SplatglError("--camera-index needs --camera (a cameras.json to pick from)")
    check_stereo_layout(args)
    projection = projection_from_args(args)
    if args.camera is not None:
        return _file_camera(args, projection, orbit_up)
    width, height = default_size(args, projection)
    if scene is None:
        return None
    up, _ = resolve_up(getattr(args, "up", None), args.scene)  # the demo has no training cameras
    return default_camera(scene, width, height, args.fov,
                          args.distance if args.distance is not None else 1.0,
                          settings.transform if settings is not None else None, up,
                          projection=projection)


def inputs_from_args(args: argparse.Namespace) -> tuple[Scene, RenderSettings, Camera]:
    """The scene, settings and camera every rendering command starts from.

    Settings and camera are read before the scene (cheap checks first: a bad option fails
    without waiting for a large scene to load).
    """
    settings = settings_from_args(args)
    camera_from_args(args, None, settings)  # the camera file and options checked early
    scene = load_scene_arg(args)
    return scene, settings, camera_from_args(args, scene, settings)


def format_timings(times: object) -> str:
    """A renderer's ``last_times`` dataclass as one line: float fields are seconds (shown in
    ms, with their total), int fields are counts and strings are already formatted (both
    shown as they are); the frame's transfers read ``per-frame uploads N bytes, read back N
    bytes, N syncs``."""
    parts, total = [], 0.0
    for name, value in vars(times).items():
        if isinstance(value, bool) or value is None or name == "capped":   # capped: a sentence,
            continue                                                        # said on its own line
        if isinstance(value, TransferCounts):   # the frame's transfers (issue 40 item 3)
            parts.append(value.text())
        elif isinstance(value, int):
            parts.append(f"{name} {value:,}")
        elif isinstance(value, str):
            parts.append(f"{name} {value}")
        else:
            parts.append(f"{name} {float(value) * 1e3:.1f} ms")
            total += float(value)
    return ", ".join(parts) + f" (stages total {total * 1e3:.1f} ms)"
