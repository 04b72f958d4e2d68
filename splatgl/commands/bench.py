"""``splatgl bench``: frame time against error for every configuration, in one run."""

from __future__ import annotations

import argparse
import shutil
import textwrap
from pathlib import Path

from ..measure.bench.early_stop_report import early_stop_table
from ..measure.bench.real_scenes import shared_scenes_dir, shared_scenes_help
from ..measure.bench.storage_report import storage_table
from ..measure.bench.report import plot, table, write_csv, write_json
from ..measure.bench.configs import configurations
from ..measure.bench.machine import describe, machine_info
from ..measure.bench.runner import BenchOptions, sort_benchmark
from ..measure.bench.scene_task import BenchSceneTask, SceneSpec, default_base, measure_scene
from ..errors import SplatglError
from ..tasks.executor import run_tasks, summary
from ._executor import add_executor_arguments, executor_from_args
from ..gl.context import renderer_name
from ..renderers.registry import check_image_size
from ..measure.evaluation.metrics import check_ssim_size
from ..writing.outputs import OutputFiles
from ..progress import StderrProgress, default_progress, enabled
from ..api import Renderer
from ..scene.settings import RenderSettings
from ._bench_modes import (add_interactive_arguments, add_lod_arguments, add_mode_arguments,
                           add_popping_arguments, add_scale_lod_arguments,
                           check_interactive_options, check_mode_options,
                           check_scale_lod_options, modes_given,
                           run_interactive_command, run_lod_command, run_popping_command,
                           run_scale_command, run_scale_lod_command)
from ._common import demo_scene_path, non_negative_int, positive_int
from ._memory import (STREAM_HELP, add_level_argument, add_memory_argument, check_scene_file,
                      memory_given, stream_level)
from ._json_output import add_json_argument, check_json_target, emit_json, json_to_stdout
from ._outputs import add_force_argument, check_out_folder

NAME = "bench"
ORDER = 40
HELP = "benchmark run time against error for renderer configurations"
DESCRIPTION = """Measure, on the same scenes and camera paths in one run, each configuration's
frame time and its error against the per-tile reference.

Rows: the default quad configuration; each knob changed alone (blend precision, quad extent,
sort keys, SH degree cap, re-sorting every N frames, per-splat math in a compute pre-pass or
the vertex shader, culling); the tile renderer and the NumPy reference; and the limit row (the
default's quads drawn with trivial shaders), so every time reads as a ratio to the best this
machine's OpenGL can do.  Each row: median frame time with its 10-90% spread over an orbit
(the camera moves every frame), per-stage times, GL timer-query draw time where the driver has
real timer queries, splats drawn, fragments shaded against fragments with alpha >= 1/255,
and PSNR / max error / share of pixels off by more than 1/255 against the reference.

Without scenes: the shared real scenes (if present) and a synthetic 150k SH3 scene; with
--quick: the bundled demo at 160x120, a few frames, one row per question (CI).  The shared
scenes folder (also the source of the --real-splats, --scale and --lod scenes) is
$SPLATGL_SHARED_SCENES when set, else ../shared/scenes from the working directory (its path
is printed at the end of this help).

examples:
  splatgl bench --quick
  splatgl bench scene.ply --width 1280 --height 720 --out bench-results
  splatgl bench --groups extent,preprocess
  splatgl bench --groups early-stop          (auto, on and off; adds a 1M-splat real-data scene)
  splatgl bench a.ply b.ply c.ply --executor ray --ray-address auto   (one scene per Ray task)"""

REAL = ["ply/donut_sh0.ply", "compressed_ply/biker.compressed.ply", "compressed_ply/guitar.compressed.ply"]


def _group_names() -> tuple[str, ...]:
    """The groups ``--groups`` may name (every row's group but the two that always run)."""
    rows = configurations(RenderSettings(), 3)
    return tuple(dict.fromkeys(r.group for r in rows if r.group not in ("default", "limit")))


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.epilog = textwrap.fill("shared real scenes: " + shared_scenes_help(), 90, break_long_words=False)
    p.add_argument("scenes", nargs="*", type=Path, help="scene files (default: see above)")
    p.add_argument("--quick", action="store_true", help="small and fast: the demo scene, few rows (CI)")
    p.add_argument("--width", type=positive_int, default=None, help="image width (default 1280; quick 160)")
    p.add_argument("--height", type=positive_int, default=None, help="image height (default 720; quick 120)")
    p.add_argument("--frames", type=positive_int, default=None,
                   help="timed frames per row (default 12; quick 4); with --scale --lod: frames "
                        "of its path step, whose memory after each frame is recorded (default 60)")
    p.add_argument("--groups", default=None,
                   help="only these comma-separated groups of rows: " + ", ".join(_group_names())
                        + " (default and limit always run)")
    p.add_argument("--synthetic", type=non_negative_int, default=None, metavar="N",
                   help="add a synthetic SH3 scene of N splats (default 150000 without scenes; "
                        "0 for none)")
    p.add_argument("--real-splats", type=non_negative_int, default=None, metavar="N",
                   help="add a scene of N splats built from jittered, rotated copies of the shared "
                        "real files (deterministic; default 1000000 with --groups early-stop and "
                        "no scene files, else none)")
    p.add_argument("--out", type=Path, default=None, metavar="DIR",
                   help="write bench.csv, bench.json and bench.png there (created if missing; "
                        "existing files of those names are replaced only with --force); "
                        "--popping, --interactive, --scale and --lod write their own JSON and "
                        "picture there")
    add_force_argument(p)
    add_json_argument(p, "the rows and the machine (bench.json's content)")
    add_mode_arguments(p)
    p.add_argument("--sizes", default=None, metavar="LIST",
                   help="--scale sizes, e.g. 0.1M,0.3M,1M,3M,6M (the default); 'k' and 'M' suffixes; "
                        "--lod sizes (default 3M,6M)")
    p.add_argument("--sh3-sizes", default=None, metavar="LIST",
                   help="--scale sizes also measured at SH degree 3 (default 1M; 'none' for none)")
    p.add_argument("--savings", action="store_true",
                   help="also run the paired rows that prove each skipped cost: SH0 against the "
                        "same scene padded to SH3, 90%% off-screen culled and not, still against "
                        "moving camera (on by default without --quick)")
    add_executor_arguments(p, "one scene per task (timings of workers running at once on one "
                              "machine share its cores: for fair timings use one worker per "
                              "machine, i.e. Ray across machines)",
                           "one task per scene")
    add_lod_arguments(p)
    add_memory_argument(p, STREAM_HELP + "; with one such SCENE: frames along an orbit, first "
                           "and median frame time, resident memory, chunks, peak RSS. With "
                           "--scale --lod: the budget of its level-of-detail builds and streamed "
                           "frames")
    add_level_argument(p)
    add_scale_lod_arguments(p)
    add_popping_arguments(p)
    add_interactive_arguments(p)


#: The interactive benchmark's built scene when no scene files are given (--real-splats).
INTERACTIVE_REAL_SPLATS = 1_000_000


def _interactive_scenes(args: argparse.Namespace) -> list[Path]:
    """``--interactive``'s scenes: the files given, else the shared real files and a scene of
    ``--real-splats`` (default 1M) built from them (cached in the temp folder)."""
    if args.scenes:
        return list(args.scenes)
    shared = shared_scenes_dir()
    scenes = [shared / r for r in REAL if (shared / r).is_file()]
    if not scenes:
        raise SplatglError(f"--interactive: no scene files given and the shared real scenes are "
                           f"not at {shared} (set SPLATGL_SHARED_SCENES)")
    n = INTERACTIVE_REAL_SPLATS if args.real_splats is None else args.real_splats
    if n:
        from ..measure.bench.scale import scene_file

        print(f"building (or reusing) the {n:,}-splat scene ...", flush=True)
        scenes.append(scene_file(n, 0))
    return scenes


def _parse_groups(text: str | None) -> frozenset[str] | None:
    if not text:
        return None
    groups = frozenset(g.strip() for g in text.split(",") if g.strip())
    valid = _group_names()
    unknown = sorted(groups - set(valid))
    if unknown or not groups:
        raise SplatglError(f"--groups: unknown group(s) {', '.join(unknown) or repr(text)}; "
                           f"valid: {', '.join(valid)}")
    return groups


def _size(args: argparse.Namespace) -> tuple[int, int, int]:
    """``(width, height, frames)``: as given, else 1280x720 and 12 frames (``--quick``: 160x120
    and 4)."""
    quick = args.quick
    return (args.width or (160 if quick else 1280), args.height or (120 if quick else 720),
            args.frames or (4 if quick else 12))


def _run_stream_bench(args: argparse.Namespace, sharded: bool) -> int:
    """``splatgl bench SCENE.lod.ply --memory SIZE``: :func:`splatgl.measure.bench.stream_bench.run_stream`
    (its figures printed, or as JSON with --json)."""
    from ..measure.bench.stream_bench import describe, run_stream
    from ..lod.io import is_lod_file
    from ..lod.stream_levels import is_chunked

    others = modes_given(args) + [m for m, on in (("--out", args.out),
                                                  ("--workers/--executor ray", sharded)) if on]
    if others:
        raise SplatglError(f"--memory streams one level of detail in one process; not with "
                           f"{', '.join(others)}")
    if len(args.scenes) == 1:
        check_scene_file(args.scenes[0])   # a missing file: 'no such file', as info says
    if len(args.scenes) != 1 or not (is_lod_file(args.scenes[0]) or is_chunked(args.scenes[0])):
        raise SplatglError("--memory: give one level-of-detail file (from 'splatgl lod', or a "
                           "Streamed SOG lod-meta.json or LCC meta.lcc) to stream, got "
                           f"{', '.join(map(str, args.scenes)) or 'none'}")
    level = stream_level(argparse.Namespace(scene=args.scenes[0], memory=args.memory,
                                            lod_level=args.lod_level))
    report = run_stream(args.scenes[0], memory_given(args), *_size(args), level=level)
    if not json_to_stdout(args):
        print(describe(report))
    if args.json is not None:
        emit_json(args, report)
    return 0


#: The files ``bench --out DIR`` writes.
BENCH_FILES = ("bench.csv", "bench.json", "bench.png")


def _write_out(out: Path, rows: list, extra: dict) -> None:
    """bench.csv, bench.json and bench.png, all or none (a folder made here goes on failure)."""
    made = not out.exists()
    out.mkdir(exist_ok=True)
    try:
        # checked before measuring (check_out_folder): an existing file here means --force
        files = OutputFiles({name: out / name for name in BENCH_FILES}, overwrite=True)
        with files:
            write_csv(files.temp("bench.csv"), rows)
            write_json(files.temp("bench.json"), rows, extra)
            plot(files.temp("bench.png"), rows)
    except BaseException:
        if made:
            shutil.rmtree(out, ignore_errors=True)
        raise


def run(args: argparse.Namespace) -> int:
    executor = executor_from_args(args)
    check_mode_options(args)    # a benchmark's options without its flag: refused, not ignored
    if args.memory is not None and not (args.scale and args.lod):   # --scale --lod: its budget
        return _run_stream_bench(args, executor.sharded)
    if args.lod_level is not None:
        raise SplatglError(f"--lod-level {args.lod_level} draws a level of a Streamed SOG or LCC "
                           "streamed from disk: give one SCENE with --memory SIZE (not with "
                           "--scale --lod)")
    if args.popping:
        if modes_given(args) != ["--popping"] or executor.sharded or args.json is not None:
            raise SplatglError("--popping runs alone in one process (not with --interactive, "
                               "--scale, --lod, --workers, --executor ray or --json; --out DIR "
                               "writes popping.json)")
        return run_popping_command(args)
    check_scale_lod_options(args)
    modes = modes_given(args)   # not --popping: it ran alone above
    if modes == ["--scale", "--lod"]:   # one benchmark: scenes larger than memory
        modes = ["--scale --lod"]
    if len(modes) > 1:     # each ran alone, the others silently left out
        raise SplatglError(f"{' and '.join(modes)} are separate benchmarks: run one at a time "
                           "(each writes its own JSON with --out DIR)")
    if (args.scale or args.lod) and executor.sharded:
        mode = modes[0]
        raise SplatglError(f"{mode} measures in one process (memory, load and frame times); "
                           "--workers and --executor ray shard the scene benchmark")
    if (args.scale or args.lod) and args.json is not None:
        mode = modes[0]
        raise SplatglError(f"--json: {mode} writes its JSON with --out DIR")
    if args.exact != "quad" and not args.interactive:
        raise SplatglError("--exact chooses the exact frame of --interactive's flight; add "
                           "--interactive (the scene benchmark has a cpu row of its own)")
    if args.interactive:
        check_interactive_options(args)          # before looking for the scenes
        return run_interactive_command(args, _interactive_scenes(args))
    if args.scale and args.lod:
        return run_scale_lod_command(args)
    if args.scale:
        return run_scale_command(args)
    if args.lod:
        return run_lod_command(args)
    quick = args.quick
    width, height, frames = _size(args)
    groups = _parse_groups(args.groups)
    check_image_size(width, height, "--width/--height: image", "quad")
    check_ssim_size(width, height, "--width/--height: image")   # the error columns
    check_out_folder(args, BENCH_FILES)
    check_json_target(args, {"--out (bench.json)": args.out / "bench.json" if args.out else None})
    options = BenchOptions(width, height, frames, error_frames=tuple(sorted({frames // 3, 2 * frames // 3, frames - 1}))
                           if not quick else (frames - 1,), quick=quick, groups=groups)
    specs = [SceneSpec(p.name, p) for p in args.scenes]
    if not specs:
        if quick:
            specs.append(SceneSpec("demo", demo_scene_path()))
        else:
            shared = shared_scenes_dir()
            specs += [SceneSpec(Path(r).name, shared / r) for r in REAL if (shared / r).is_file()]
    n_syn = args.synthetic if args.synthetic is not None else (150_000 if not args.scenes and not quick else 0)
    if n_syn:
        specs.append(SceneSpec(f"synthetic-{n_syn // 1000}k-sh3", synthetic=n_syn))
    n_real = args.real_splats
    if n_real is None:
        n_real = 1_000_000 if groups and "early-stop" in groups and not args.scenes and not quick else 0
    if n_real:
        specs.append(SceneSpec(f"real-{n_real / 1e6:g}M", real_splats=n_real))
    if not specs:
        raise SplatglError(f"nothing to measure: no scenes given, none found in {shared_scenes_help()}, "
                           "and --synthetic 0")
    savings = args.savings or not quick
    run = None
    if executor.sharded:    # one scene per task, each in its own worker
        run = run_tasks([BenchSceneTask(spec, options, savings) for spec in specs], executor, "steps",
                        default_progress())
        rows = [row for scene_rows, _ in run.values for row in scene_rows]
        machine = run.values[0][1]
    else:
        progress = StderrProgress() if enabled() else None
        rows = []
        with Renderer() as renderer:
            check_image_size(width, height, "--width/--height: image", "quad", renderer.ctx)
            machine = machine_info(renderer_name(renderer.ctx),    # before the context closes
                                   default_row=default_base(renderer.ctx))
            for spec in specs:
                rows += measure_scene(renderer, spec, spec.load(), options, savings, progress)
    sort_ms = sort_benchmark(100_000 if quick else 1_000_000)
    extra = {"width": width, "height": height, "frames": frames,
             "sort_exact_ms": sort_ms, "sort_keys": 100_000 if quick else 1_000_000,
             "renderer": machine["gl_renderer"], "machine": machine}
    if run is not None:  # where each scene was measured
        extra["workers"] = [{"scene": spec.name, "worker": str(r.worker), "seconds": r.seconds,
                             "rows": r.done.count} for spec, r in zip(specs, run.reports)]
    if args.out is not None:
        _write_out(args.out, rows, extra)
    report = {**extra, "rows": [r.as_dict() for r in rows]}
    if json_to_stdout(args):
        emit_json(args, report)
        return 0
    print(describe(machine))
    print(f"{width}x{height}, {frames} frames per row along an orbit")
    print(table(rows))
    print(f"\nexact sort of {extra['sort_keys']} depth keys: {sort_ms:.1f} ms (median)")
    stop_table = early_stop_table(rows, width * height)
    if stop_table:
        print("\n" + stop_table)
    store_table = storage_table(rows)
    if store_table:
        print("\n" + store_table)
    defaults = [r for r in rows if r.config == "default"]
    for r in defaults:
        print(f"target check {r.scene}: default at {r.limit_ratio:.2f}x the limit row "
              f"(target <= 1.5), fragment efficiency {r.fragment_efficiency:.3f} (target >= 0.5)")
    if run is not None:
        print(summary(run, "rows"))
    if args.out is not None:
        print(f"wrote {args.out / 'bench.csv'}, bench.json, bench.png")
    if args.json is not None:
        emit_json(args, report)
    return 0
