"""Argument groups shared by the commands that render (render, compare, view, bench)."""

from __future__ import annotations

import argparse
from pathlib import Path

from ..camera import Camera
from ..camera_io import load_camera
from ..errors import SplatglError
from ..formats import load_scene
from ..render import default_camera
from ..scene import Scene
from ..settings import Convention, Precision, Preprocess, QuadExtent, RenderSettings, SortKey
from ..transform import parse_transform


def demo_scene_path() -> Path:
    """The bundled demo scene: inside the installed package, or the repository's scenes/."""
    here = Path(__file__).resolve().parent.parent
    for candidate in (here / "scenes" / "demo.ply", here.parent / "scenes" / "demo.ply"):
        if candidate.is_file():
            return candidate
    raise SplatglError(f"bundled demo scene not found next to {here} (broken installation?)")


def parse_rgb(text: str) -> tuple[float, float, float]:
    try:
        parts = [float(p) for p in text.split(",")]
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected R,G,B numbers, got {text!r}") from None
    if len(parts) != 3:
        raise argparse.ArgumentTypeError(f"expected 3 comma-separated values, got {text!r}")
    return tuple(parts)


def add_scene_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("scene", nargs="?", type=Path, default=None,
                   help="scene file (.ply, .splat, ...); default: the bundled demo scene")
    p.add_argument("--drop-invalid", action="store_true",
                   help="drop rows with NaN/Inf values or zero quaternions (with a warning that "
                        "counts them) instead of rejecting the file")


def add_camera_arguments(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group("camera")
    g.add_argument("--camera", type=Path, default=None,
                   help="camera file: splatgl single-camera JSON, or a 3DGS cameras.json "
                        "(default: a view that frames the scene)")
    g.add_argument("--camera-index", type=int, default=0,
                   help="which camera of a cameras.json list (default 0)")
    g.add_argument("--width", type=int, default=None,
                   help="image width in pixels (default 1280, or the camera file's; with a camera "
                        "file the intrinsics are scaled)")
    g.add_argument("--height", type=int, default=None, help="image height in pixels (default 720)")
    g.add_argument("--fov", type=float, default=None,
                   help="vertical field of view of the default camera, degrees (default 50)")
    g.add_argument("--orthographic", action="store_true",
                   help="make the default camera orthographic, zoomed to frame the scene")
    g.add_argument("--distance", type=float, default=1.0, metavar="SCALE",
                   help="default camera distance as a multiple of the framing distance "
                        "(default 1; 0.5 is twice as close)")


def add_settings_arguments(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group("rendering")
    g.add_argument("--background", type=parse_rgb, default=(0.0, 0.0, 0.0), metavar="R,G,B",
                   help="background colour composited behind the splats, 0-1 (default 0,0,0)")
    g.add_argument("--precision", choices=[m.value for m in Precision], default="rgba32f",
                   help="blend target of the quad path (default rgba32f)")
    g.add_argument("--extent", choices=[m.value for m in QuadExtent], default="ellipse",
                   help="quad size: 'ellipse' = opacity-aware ellipse axes (default), 'square' = "
                        "the reference's 3-sigma square")
    g.add_argument("--near", type=float, default=None,
                   help="near-plane distance in world units (default: min(0.2, 1%% of the "
                        "scene's robust radius))")
    g.add_argument("--antialias", action="store_true",
                   help="apply the reference's antialiasing opacity compensation")
    g.add_argument("--sh-degree", type=int, default=None, choices=range(4),
                   help="cap the SH degree evaluated (default: the scene's)")
    g.add_argument("--preprocess", choices=[m.value for m in Preprocess], default=None,
                   help="where the quad path's per-splat math runs: 'vertex' shader (per corner) "
                        "or a 'compute' pre-pass (per splat); default: what the benchmark chose")
    g.add_argument("--sort", choices=[m.value for m in SortKey], default="exact",
                   help="quad path depth keys: exact 32-bit (default) or 16-bit buckets")
    g.add_argument("--convention", choices=[m.value for m in Convention], default="inria",
                   help="rules of the NumPy reference: 'inria' = the 3DGS rasterizer (default), "
                        "'gsplat' = per-axis opacity-aware extent up to 3.33 sigma, alpha clamp 0.999")
    g.add_argument("--early-stop", choices=["on", "off"], default=None,
                   help="quad path early termination: stop shading pixels whose transmittance "
                        "fell below 1e-4 and drop splats that land only on such pixels "
                        "(default off, chosen by the benchmark on llvmpipe)")
    g.add_argument("--half-sh", action="store_true",
                   help="store SH coefficients as float16 in the quad path (half the memory)")
    g.add_argument("--transform", type=str, default=None, metavar="JSON",
                   help='place the scene in the world: inline JSON or a JSON file, e.g. '
                        '\'{"rotate_deg": [0, 90, 0], "translate": [0, 0, 1], "scale": 2}\' '
                        "(rotations about x, then y, then z; or \"rotation\": 3x3). SH is "
                        "evaluated in the scene's own frame")


def load_scene_arg(args: argparse.Namespace) -> Scene:
    path = args.scene if args.scene is not None else demo_scene_path()
    return load_scene(path, drop_invalid=args.drop_invalid)


def settings_from_args(args: argparse.Namespace) -> RenderSettings:
    model = parse_transform(args.transform) if args.transform else None
    optional = {"preprocess": args.preprocess} if args.preprocess else {}
    if getattr(args, "early_stop", None) is not None:
        optional["early_stop"] = args.early_stop == "on"
    return RenderSettings(background=args.background, precision=args.precision, extent=args.extent,
                          near=args.near, antialias=args.antialias, sh_degree=args.sh_degree,
                          model=model, sort_key=args.sort, half_sh=args.half_sh,
                          convention=args.convention, **optional)


def camera_from_args(args: argparse.Namespace, scene: Scene, settings: RenderSettings | None = None) -> Camera:
    for name in ("width", "height"):
        value = getattr(args, name)
        if value is not None and not 1 <= value <= 16384:
            raise SplatglError(f"--{name} must be between 1 and 16384, got {value}")
    if args.camera is not None:
        cam = load_camera(args.camera, args.camera_index)
        if args.width or args.height:
            w = args.width or round(cam.width * args.height / cam.height)
            h = args.height or round(cam.height * args.width / cam.width)
            cam = cam.resized(w, h)
        return cam
    if args.fov is not None and not 0.0 < args.fov < 180.0:
        raise SplatglError(f"--fov must be in (0, 180) degrees, got {args.fov}")
    if not args.distance > 0.0:
        raise SplatglError(f"--distance must be positive, got {args.distance}")
    cam = default_camera(scene, args.width or 1280, args.height or 720,
                         args.fov if args.fov is not None else 50.0, args.distance,
                         settings.model if settings is not None else None)
    if getattr(args, "orthographic", False):
        scale = settings.model.scale if settings is not None and settings.model else 1.0
        radius = max(scene.robust_radius * scale, 1e-9) * args.distance
        cam = Camera.orthographic(cam.width, cam.height, min(cam.width, cam.height) / (2.1 * radius),
                                  cam.world_to_camera)
    return cam


def inputs_from_args(args: argparse.Namespace) -> tuple[Scene, RenderSettings, Camera]:
    """The scene, settings and camera every rendering command starts from."""
    scene = load_scene_arg(args)
    settings = settings_from_args(args)
    return scene, settings, camera_from_args(args, scene, settings)
