"""``splatgl bench --scale`` and ``--lod``: their options mapped onto the benchmarks
(:func:`splatgl.measure.bench.scale.run_scale`, :func:`splatgl.measure.bench.lod_bench.run_lod`)."""

from __future__ import annotations

import argparse
import math
from pathlib import Path

from ..measure.bench.lod_bench import PATH_SETS
from ..measure.bench.scale import SH3_SIZES, SIZES, parse_sizes
from ..errors import SplatglError
from ._frame_budget import add_target_fps_argument
from ._outputs import check_out_folder


#: The benchmarks ``splatgl bench`` runs instead of the scene benchmark: each flag and its help.
MODES = {
    "interactive": "the interactive benchmark instead: a scripted 10 s camera flight (orbit, "
                   "fly-in, rest) through the viewer's frame-time budget on each scene: frames a "
                   "second while moving, PSNR of the moving frames against the exact render, time "
                   "from rest to exact, input latency (see splatgl/measure/bench/flight.py). "
                   "Default scenes: the shared real files and a 1M-splat scene built from them "
                   "(--real-splats)",
    "scale": "the scale benchmark instead: scenes of --sizes splats built from the shared real "
             "files (and one SH3 size), load time, peak memory, GPU bytes per splat, "
             "cull/sort/pre-pass/draw and tile frame times, CPU and GPU sort, log-log slopes (see "
             "splatgl/measure/bench/scale.py); with --lod: scenes larger than memory (default "
             "1M,5M,20M,100M) written to a scratch folder, their out-of-core level of detail, lazy "
             "open, streamed first frame, flight and far-view PSNR, each step's time and peak "
             "memory (splatgl/measure/bench/scale_lod.py)",
    "lod": "the level-of-detail benchmark instead: scenes of --sizes splats (default 3M,6M) and "
           "their hierarchies, frame time, PSNR/SSIM against full detail and popping between "
           "frames along camera paths, per cut (see splatgl/measure/bench/lod_bench.py)",
    "popping": "the popping benchmark instead: an orbit and a fly-through in small steps of each "
               "scene (default: the shared real scenes), every pair of frames warped and scored "
               "for popping, the global order against the per-pixel order on the quad path, tile "
               "renderer and reference (default 640x360, 16 frames a path, --frames at least 2; "
               "see splatgl/measure/bench/popping_bench.py and docs/fidelity.md)",
}


def add_mode_arguments(p: argparse.ArgumentParser) -> None:
    """``--interactive``, ``--scale``, ``--lod``, ``--popping`` (:data:`MODES`)."""
    for name, help in MODES.items():
        p.add_argument(f"--{name}", action="store_true", help=help)


def modes_given(args: argparse.Namespace) -> list[str]:
    """The flags of :data:`MODES` given, in its order (``--scale --lod`` is two)."""
    return [f"--{name}" for name in MODES if getattr(args, name)]


#: The options only one benchmark reads: (the flags that turn it on, what it is, their dests).
#: Given without any of those flags, they are refused (they would be silently ignored).  A flag
#: "scale lod" is two that must be given together.
MODE_OPTIONS = (
    (("popping",), "the popping benchmark", ("popping_configs", "popping_metric", "popping_window")),
    (("interactive",), "the interactive benchmark", ("target_fps",)),
    (("lod",), "the level-of-detail benchmark", ("lod_thresholds", "lod_budgets", "lod_blend",
                                                 "lod_paths")),
    (("scale", "lod"), "the scale and level-of-detail benchmarks", ("sizes",)),
    (("scale",), "the scale benchmark", ("sh3_sizes",)),
    (("scale lod",), "the out-of-core scale benchmark", ("scratch",)),
)


def check_mode_options(args: argparse.Namespace) -> None:
    """One line naming the options of a benchmark given without the flag that runs it
    (:data:`MODE_OPTIONS`), before any work."""
    for flags, what, dests in MODE_OPTIONS:
        given = ["--" + d.replace("_", "-") for d in dests if getattr(args, d, None) is not None]
        if given and not any(all(getattr(args, w) for w in f.split()) for f in flags):
            add = " or ".join(" ".join(f"--{w}" for w in f.split()) for f in flags)
            raise SplatglError(f"{', '.join(given)}: {'options' if len(given) > 1 else 'an option'} "
                               f"of {what}; add {add}")


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


def add_scale_lod_arguments(p: argparse.ArgumentParser) -> None:
    """The options of ``splatgl bench --scale --lod`` (scenes larger than memory) besides
    ``--memory`` (:func:`._memory.add_memory_argument`, the budget of its build and frames)."""
    p.add_argument("--keep-scenes", action="store_true",
                   help="--scale --lod: keep the scene and level-of-detail files in the scratch "
                        "folder (default: removed after each size)")
    p.add_argument("--scratch", type=Path, default=None, metavar="DIR",
                   help="--scale --lod: the scratch folder (default: a new one in the temp dir), "
                        "its files kept as with --keep-scenes; a size whose scale-N.ply and "
                        "scale-N.lod.ply are there already is not built again (its build "
                        "figures from build-N.json), so a rerun measures the frames only; a "
                        "stale file there is refused")


#: Options of the other benchmarks that --scale --lod does not read.
_NOT_SCALE_LOD = ("sh3_sizes", "lod_thresholds", "lod_budgets", "lod_blend", "lod_paths")


def run_scale_lod_command(args: argparse.Namespace) -> int:
    """``splatgl bench --scale --lod``: :func:`splatgl.measure.bench.scale_lod.run_scale_lod`."""
    from ..measure.bench.machine import describe, probe_machine
    from ..measure.bench.scale_lod import SIZES, ScaleLodOptions, run_scale_lod
    from ..measure.bench.scale_lod_report import table
    from ._memory import memory_budget

    given = ["--" + n.replace("_", "-") for n in _NOT_SCALE_LOD if getattr(args, n, None) is not None]
    if given:
        raise SplatglError(f"{', '.join(given)}: not read by --scale --lod (it measures the "
                           "default cut of SH0 scenes; the options are --sizes, --width, --height, "
                           "--memory, --frames, --keep-scenes, --scratch, --out)")
    sizes = parse_sizes(args.sizes, SIZES, "--sizes")
    if not sizes:
        raise SplatglError("--sizes: --scale --lod needs at least one size")
    memory = memory_budget(args)   # as splatgl lod --memory: half this machine's RAM by default
    check_out_folder(args, ("scale-lod.json", "scale-lod.png"))   # before any measuring
    options = ScaleLodOptions(sizes=sizes, memory=memory, width=args.width or 1280,
                              height=args.height or 720, scratch=args.scratch,
                              path_frames=args.frames or ScaleLodOptions.path_frames,
                              keep_scenes=args.keep_scenes or args.scratch is not None)
    machine = probe_machine()
    print(describe(machine), flush=True)
    report = run_scale_lod(options, args.out, machine, log=lambda m: print(m, flush=True))
    print(table(report["rows"], options.memory))
    if args.out is not None:
        print(f"wrote {args.out / 'scale-lod.json'}, scale-lod.png")
    return 0


def check_scale_lod_options(args: argparse.Namespace) -> None:
    """--keep-scenes belongs to --scale --lod."""
    if args.keep_scenes and not (args.scale and args.lod):
        raise SplatglError("--keep-scenes: an option of the out-of-core scale benchmark; add "
                           "--scale --lod")


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
    from ..measure.bench.lod_bench import run_lod

    paths = args.lod_paths or "coarse"
    if paths not in PATH_SETS:
        raise SplatglError(f"--lod-paths: expected one of {', '.join(PATH_SETS)}, got {paths!r}")
    bands = _numbers(args.lod_blend or "2,1", "--lod-blend")
    check_out_folder(args, ("lod.json", "lod.png"))   # before any measuring
    if min(bands) < 1:
        raise SplatglError(f"--lod-blend: bands are ratios of at least 1, got {args.lod_blend!r}")
    run_lod(parse_sizes(args.sizes or "3M,6M", (), "--sizes"), args.width or 1280,
            args.height or 720, args.frames or 5,
            _numbers(args.lod_thresholds or "1,2", "--lod-thresholds"),
            list(parse_sizes(args.lod_budgets or "1M,0.3M", (), "--lod-budgets")), bands, paths,
            args.out, log=lambda m: print(m, flush=True))
    return 0


def add_popping_arguments(p: argparse.ArgumentParser) -> None:
    """The --popping options of ``splatgl bench``."""
    from ..measure.bench.popping_bench import CONFIGS
    from ..measure.evaluation.popping import METRICS

    p.add_argument("--popping-configs", default=None, metavar="LIST",
                   help="--popping configurations, comma-separated: " + ", ".join(CONFIGS)
                        + " (default all)")
    p.add_argument("--popping-metric", choices=METRICS, default=None,
                   help="--popping error metric: flip (NVIDIA FLIP, the 'fidelity' extra; the "
                        "default where installed) or own (the fallback: a neighbourhood-min colour "
                        "difference, splatgl/measure/evaluation/popping.py)")
    p.add_argument("--popping-window", type=int, default=None, metavar="N",
                   help="--popping: the tile renderer's per-pixel window of the 'tile per-pixel' "
                        "configuration (1-32, default 32, as render --order-window)")


def run_popping_command(args: argparse.Namespace) -> int:
    """``splatgl bench --popping``."""
    import json
    from dataclasses import asdict
    from pathlib import Path

    from ..api import Renderer
    from ..measure.bench.machine import describe, machine_info
    from ..measure.bench.popping_bench import CONFIGS, SCENES, PoppingOptions, measure_scene, table
    from ..measure.bench.real_scenes import shared_scenes_dir, shared_scenes_help
    from ..measure.evaluation.popping import default_metric
    from ..formats import load_scene
    from ..gl.context import renderer_name
    from ..scene.settings import DEFAULT_ORDER_WINDOW, MAX_ORDER_WINDOW
    from ..writing.atomic import atomic_write_text

    configs = tuple(c.strip() for c in (args.popping_configs or ",".join(CONFIGS)).split(",") if c.strip())
    unknown = [c for c in configs if c not in CONFIGS]
    if unknown or not configs:
        raise SplatglError(f"--popping-configs: unknown {', '.join(unknown) or repr(args.popping_configs)}; "
                           f"valid: {', '.join(CONFIGS)}")
    window = DEFAULT_ORDER_WINDOW if args.popping_window is None else args.popping_window
    if not 1 <= window <= MAX_ORDER_WINDOW:     # 0 was taken as "the default"
        raise SplatglError(f"--popping-window must be 1..{MAX_ORDER_WINDOW}, got {window}")
    if args.popping_window is not None and "tile per-pixel" not in configs:
        raise SplatglError(f"--popping-window {window}: the window is the 'tile per-pixel' "
                           "configuration's, which --popping-configs leaves out")
    options = PoppingOptions(args.width or 640, args.height or 360, args.frames or 16, window, configs,
                             args.popping_metric or default_metric())
    if options.metric == "flip":
        from ..measure.evaluation.popping import flip_available
        if not flip_available():
            raise SplatglError("--popping-metric flip needs flip-evaluator (pip install "
                               "'splatgl[fidelity]'); without it the metric is 'own'")
    if args.scenes:
        scenes = [(Path(p), None) for p in args.scenes]
    else:
        shared = shared_scenes_dir()
        scenes = [(shared / rel, up) for rel, up in SCENES if (shared / rel).is_file()]
        if not scenes:
            raise SplatglError(f"--popping: no scenes given and none found in {shared_scenes_help()}")
    check_out_folder(args, ("popping.json",))   # before any measuring
    rows = []
    with Renderer() as renderer:
        machine = machine_info(renderer_name(renderer.ctx))
        print(describe(machine), flush=True)
        print(f"popping: {options.width}x{options.height}, {options.frames} frames a path, metric "
              f"{options.metric}, per-pixel window {window} (tile)", flush=True)
        for path, up in scenes:
            scene = load_scene(path)
            rows += measure_scene(renderer, path.name, scene, path, up, options,
                                  log=lambda m: print(m, flush=True))
    print(table(rows))
    if args.out is not None:
        args.out.mkdir(parents=True, exist_ok=True)
        target = args.out / "popping.json"
        atomic_write_text(target, json.dumps({"machine": machine, "options": asdict(options),
                                              "rows": rows}, indent=1))
        print(f"wrote {target}")
    return 0


def run_scale_command(args: argparse.Namespace) -> int:
    """``splatgl bench --scale``."""
    from ..measure.bench.machine import describe, probe_machine
    from ..measure.bench.scale import ScaleOptions, run_scale
    from ..measure.bench.scale_report import plot, table, write_json

    sizes = parse_sizes(args.sizes, SIZES, "--sizes")
    check_out_folder(args, ("scale.json", "scale.png"))   # before any measuring
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
    add_target_fps_argument(p, "--interactive's frame-time budget in frames a second, as "
                               "splatgl view's")
    p.add_argument("--exact", choices=("quad", "cpu"), default="quad",
                   help="--interactive: the renderer of the exact frame at rest, which the moving "
                        "frames are scored against (cpu: the CPU renderer after quad drafts, as "
                        "splatgl view --renderer cpu; needs the fast extra; default quad)")


def check_interactive_options(args: argparse.Namespace) -> float | None:
    """``--interactive``'s frame rate (None: the renderer's default), checked before any scene
    is looked for."""
    from ..interactive.budget import check_fps

    fps = check_fps(args.target_fps)
    if fps == 0.0:
        raise SplatglError("--interactive measures the frame-time budget: --target-fps must be positive")
    return fps


def run_interactive_command(args: argparse.Namespace, scenes: list) -> int:
    """``splatgl bench --interactive`` over ``scenes`` (paths; the caller's defaults)."""
    from ..api import Renderer
    from ..measure.bench.flight import fly
    from ..measure.bench.flight_report import plot, table, write_json
    from ..measure.bench.machine import describe, probe_machine
    from ..formats import load_scene
    from ..interactive.session import default_fps

    fps = check_interactive_options(args)
    check_out_folder(args, ("interactive.json", "interactive.png"))   # before any flight
    if args.exact == "cpu":   # compiled (first use) or loaded now, not in a flight's first rest
        from ..renderers.cpu import prepare
        prepare()
    machine = probe_machine()
    print(describe(machine), flush=True)
    results = []
    with Renderer() as renderer:
        fps = fps or default_fps(renderer)
        for path in scenes:
            print(f"loading {path} ...", flush=True)
            scene = load_scene(path)
            results.append(fly(renderer, scene, path.name.split(".")[0], args.width or 1280,
                               args.height or 720, fps, log=lambda m: print(m, flush=True),
                               exact_kind=args.exact))
    print(f"interactive benchmark at a {1e3 / fps:.0f} ms budget, exact frames by the "
          f"{args.exact} renderer; " + describe(machine))
    print(table(results))
    if args.out is not None:
        args.out.mkdir(parents=True, exist_ok=True)
        write_json(args.out / "interactive.json", results,
                   {"cpu": machine["cpu"], "gl_renderer": machine["gl_renderer"], "machine": machine})
        plot(args.out / "interactive.png", results)
        print(f"wrote {args.out / 'interactive.json'}, interactive.png")
    return 0
