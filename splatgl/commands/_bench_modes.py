"""``splatgl bench --scale`` and ``--lod``: their options mapped onto the benchmarks
(:func:`splatgl.bench.scale.run_scale`, :func:`splatgl.bench.lod_bench.run_lod`)."""

from __future__ import annotations

import argparse
import math

from ..bench.lod_bench import PATH_SETS
from ..bench.scale import SH3_SIZES, SIZES, parse_sizes
from ..errors import SplatglError


def add_lod_arguments(p: argparse.ArgumentParser) -> None:
    """The --lod options of ``splatgl bench``."""
    p.add_argument("--lod-thresholds", default=None, metavar="LIST",
                   help="--lod pixel thresholds (default 1,2)")
    p.add_argument("--lod-budgets", default=None, metavar="LIST",
                   help="--lod splat budgets, at the first band (default 1M,0.3M; 'none')")
    p.add_argument("--lod-blend", default=None, metavar="LIST",
                   help="--lod transition bands, ratios (default 2,1: blended and hard cuts)")
    p.add_argument("--lod-paths", default=None, choices=PATH_SETS,
                   help="--lod camera paths: coarse (orbit and far-to-close fly-through, the "
                        "default), fine (small steps, for popping between frames) or switch "
                        "(small steps across the distance where the first threshold's cut "
                        "gives way to the leaves: the popping of that switch)")


def _numbers(text: str, flag: str) -> list[float]:
    try:
        values = [float(t) for t in text.split(",")]
    except ValueError:
        raise SplatglError(f"{flag}: expected comma-separated numbers, got {text!r}") from None
    if not values or not all(math.isfinite(v) and v > 0 for v in values):
        raise SplatglError(f"{flag}: every value must be a finite number > 0, got {text!r}")
    return values


def run_lod_command(args: argparse.Namespace) -> int:
    """``splatgl bench --lod``."""
    from ..bench.lod_bench import run_lod

    paths = args.lod_paths or "coarse"
    if paths not in PATH_SETS:
        raise SplatglError(f"--lod-paths: expected one of {', '.join(PATH_SETS)}, got {paths!r}")
    bands = _numbers(args.lod_blend or "2,1", "--lod-blend")
    if min(bands) < 1:
        raise SplatglError(f"--lod-blend: bands are ratios of at least 1, got {args.lod_blend!r}")
    run_lod(parse_sizes(args.sizes or "3M,6M", (), "--sizes"), args.width or 1280,
            args.height or 720, args.frames or 5,
            _numbers(args.lod_thresholds or "1,2", "--lod-thresholds"),
            list(parse_sizes(args.lod_budgets or "1M,0.3M", (), "--lod-budgets")), bands, paths,
            args.out, log=lambda m: print(m, flush=True))
    return 0


def run_scale_command(args: argparse.Namespace) -> int:
    """``splatgl bench --scale``."""
    from ..bench.machine import describe, probe_machine
    from ..bench.scale import ScaleOptions, run_scale
    from ..bench.scale_report import plot, table, write_json

    sizes = parse_sizes(args.sizes, SIZES, "--sizes")
    sh3 = parse_sizes(args.sh3_sizes, SH3_SIZES, "--sh3-sizes")
    resolutions = ((args.width, args.height),) if args.width and args.height else ScaleOptions.resolutions
    frames = args.frames or ScaleOptions.frames
    options = ScaleOptions(sizes=sizes, sh3_sizes=sh3, resolutions=resolutions, frames=frames)
    machine = probe_machine()  # first: a run on the wrong device is seen before it starts
    print(describe(machine), flush=True)
    rows = run_scale(options, log=lambda m: print(m, flush=True))
    if not rows:
        raise SplatglError("scale benchmark: no size could be measured")
    extra = {"cpu": machine["cpu"], "gl_renderer": machine["gl_renderer"], "frames": frames,
             "machine": machine}
    print(f"scale benchmark, median of {frames} frames along an orbit per size and resolution; "
          + describe(machine))
    print(table(rows))
    if args.out is not None:
        args.out.mkdir(parents=True, exist_ok=True)
        write_json(args.out / "scale.json", rows, extra)
        plot(args.out / "scale.png", rows)
        print(f"wrote {args.out / 'scale.json'}, scale.png")
    return 0


def add_interactive_arguments(p: argparse.ArgumentParser) -> None:
    """The --interactive options of ``splatgl bench``."""
    p.add_argument("--interactive", action="store_true",
                   help="the interactive benchmark instead: a scripted 10 s camera flight (orbit, "
                        "fly-in, rest) through the viewer's frame-time budget on each scene: "
                        "frames a second while moving, PSNR of the moving frames against the exact "
                        "render, time from rest to exact, input latency (see "
                        "splatgl/bench/flight.py). Default scenes: the shared real files and a "
                        "1M-splat scene built from them (--real-splats)")
    p.add_argument("--target-fps", type=float, default=None, metavar="F",
                   help="--interactive's frame-time budget (default: 10 on software OpenGL, 60 on "
                        "a GPU, as splatgl view)")


def run_interactive_command(args: argparse.Namespace, scenes: list) -> int:
    """``splatgl bench --interactive`` over ``scenes`` (paths; the caller's defaults)."""
    from ..api import Renderer
    from ..bench.flight import fly
    from ..bench.flight_report import plot, table, write_json
    from ..bench.machine import describe, probe_machine
    from ..formats import load_scene
    from ..interactive.budget import check_fps
    from ..interactive.session import default_fps

    fps = check_fps(args.target_fps)
    if fps == 0.0:
        raise SplatglError("--interactive measures the frame-time budget: --target-fps must be positive")
    machine = probe_machine()
    print(describe(machine), flush=True)
    results = []
    with Renderer() as renderer:
        fps = fps or default_fps(renderer)
        for path in scenes:
            print(f"loading {path} ...", flush=True)
            scene = load_scene(path)
            results.append(fly(renderer, scene, path.name.split(".")[0], args.width or 1280,
                               args.height or 720, fps, log=lambda m: print(m, flush=True)))
    print(f"interactive benchmark at a {1e3 / fps:.0f} ms budget; " + describe(machine))
    print(table(results))
    if args.out is not None:
        args.out.mkdir(parents=True, exist_ok=True)
        write_json(args.out / "interactive.json", results,
                   {"cpu": machine["cpu"], "gl_renderer": machine["gl_renderer"], "machine": machine})
        plot(args.out / "interactive.png", results)
        print(f"wrote {args.out / 'interactive.json'}, interactive.png")
    return 0
