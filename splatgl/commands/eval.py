"""``splatgl eval``: render every camera of a dataset and score it against the photographs."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from ..renderers.registry import names as renderer_names
from ..writing.atomic import atomic_write_text
from ..datasets.dataset import MAX_WIDTH, Split, load_dataset
from ..datasets.sources import select_indices
from ..errors import SplatglError
from ..tasks.executor import summary
from ._executor import add_executor_arguments, executor_from_args
from ..measure.evaluation.evaluate import RenderFiles, evaluate, worst_sheet
from ..imagefiles.frame_targets import FrameTarget
from ..imagefiles.image_formats import FORMAT_NAMES
from ..imagefiles.images import check_image_suffix, write_image
from ..progress import default_progress
from ..api import Renderer
from ..scene.settings import RendererKind
from ._common import (add_scene_arguments, add_settings_arguments, check_convention, demo_scene_path,
                      load_scene_arg, settings_from_args)
from ._layers import add_layer_arguments, layer_files, named_layers
from ._memory import (STREAM_HELP, add_level_argument, add_memory_argument, memory_given,
                      stream_level, streamed_frames)
from ._spz_axes import check_not_sharded
from ._json_output import add_json_argument, check_json_target, emit_json, json_to_stdout
from ._outputs import add_force_argument, check_outputs, output_files

NAME = "eval"
ORDER = 25
HELP = "PSNR and SSIM of a scene's renders against a dataset's photographs"
DESCRIPTION = """Render every camera of a dataset and compare each render with its photograph:
PSNR and SSIM per view and their means, as a table (and CSV/JSON files).

The dataset is a COLMAP folder (sparse/0 + images/) or a NeRF/nerfstudio folder
(transforms.json, or transforms_train/test.json).  Each camera is rendered at its photograph's
size (--images images_4 picks a downscaled folder); photographs wider than 1600 px are
downscaled to 1600 as 3DGS does (--max-width 0 keeps them). --split test takes every 8th view
from the first (3DGS's --eval convention). RGBA photographs are composited over --background.
SSIM: Wang et al. 2004, 11x11 Gaussian window (sigma 1.5), valid region, mean over RGB (the
same as scikit-image with gaussian_weights=True, use_sample_covariance=False).

examples:
  splatgl eval point_cloud.ply --dataset garden --images images_4 --split test
  splatgl eval lego.ply --dataset nerf_synthetic/lego --split test --background 1,1,1 --json lego.json
  splatgl eval scene.ply --dataset garden --json - | jq .mean        (the JSON alone on stdout)
  splatgl eval scene.ply --dataset garden --csv scores.csv --sheet worst.png --worst 4
  splatgl eval scene.ply --dataset garden --workers 2          (views split over 2 processes)
  splatgl eval scene.ply --dataset garden --renders out --format exr --layers depth,normal
  splatgl eval scene.ply --dataset /shared/garden --executor ray --ray-address auto"""


def add_arguments(p: argparse.ArgumentParser) -> None:
    add_scene_arguments(p)
    g = p.add_argument_group("dataset")
    g.add_argument("--dataset", type=Path, required=True, metavar="DIR",
                   help="dataset folder: COLMAP (sparse/0, images/) or transforms.json")
    g.add_argument("--images", default=None, metavar="FOLDER",
                   help="photograph folder name, e.g. images_4 (default images)")
    g.add_argument("--split", choices=[s.value for s in Split], default="all",
                   help="all views (default), or the train/test split (every 8th view is a test view)")
    g.add_argument("--select", default=None, metavar="RANGES",
                   help="only these views of the split (start:stop:step and/or indices)")
    g.add_argument("--max-width", type=int, default=MAX_WIDTH,
                   help=f"downscale wider photographs to this width (default {MAX_WIDTH}, 3DGS's rule; 0: never)")
    g.add_argument("--renderer", choices=renderer_names(), default="quad",
                   help="renderer (default quad)")
    o = p.add_argument_group("reports")
    o.add_argument("--csv", type=Path, default=None, metavar="FILE", help="write per-view scores and means as CSV")
    add_json_argument(o, "per-view scores and means")
    o.add_argument("--sheet", type=Path, default=None, metavar="FILE",
                   help="write a picture of the worst views: render | photograph | error heat map")
    o.add_argument("--worst", type=int, default=4, help="views on the sheet (default 4)")
    o.add_argument("--renders", type=Path, default=None, metavar="DIR",
                   help="also write each view's render to DIR/<photograph name>.<format>, with the "
                        "--layers asked for (an .exr per view, or a .png and a picture per layer)")
    o.add_argument("--format", default=None, choices=FORMAT_NAMES,
                   help="image format of --renders (default png)")
    add_force_argument(o)
    add_layer_arguments(p, under=False)
    add_memory_argument(p, STREAM_HELP + "; every view waits for its chunks")
    add_level_argument(p)
    add_settings_arguments(p)
    add_executor_arguments(p, "contiguous chunks of the views (the scores merge into the same "
                              "table, CSV and JSON as one process's)",
                           "Ray tasks of up to 32 views; the dataset must be on a file system "
                           "every node shares")


def run(args: argparse.Namespace) -> int:
    if args.worst < 1:
        raise SplatglError(f"--worst must be at least 1, got {args.worst}")
    if args.max_width < 0:
        raise SplatglError(f"--max-width must be 0 or positive, got {args.max_width}")
    check_convention(args, args.renderer)
    if args.sheet is not None:
        check_image_suffix(args.sheet, "--sheet")
    check_json_target(args, {"--csv": args.csv, "--sheet": args.sheet},
                      {"--dataset": _dataset_files(args.dataset, [])})
    renders = _render_files(args)
    # every report path checked before the views are scored (the same file twice, a missing
    # folder, an input, an existing file without --force); the reports are then written all
    # or none
    json_file = None if json_to_stdout(args) else args.json
    reports = {"--csv": args.csv, "--json": json_file, "--sheet": args.sheet}
    views = load_dataset(args.dataset, args.images, args.split, args.max_width)
    if args.select:
        views = [views[i] for i in select_indices(args.select, len(views), str(args.dataset))]
    photographs = {"--dataset": _dataset_files(args.dataset, views)}
    outputs = output_files(args, reports, photographs)   # nor a photograph or camera file
    if renders is not None:
        renders.check(views)
        check_outputs(args, [p for v in views for p in renders.frames.files(v.camera).paths(renders.path(v))],
                      "--renders", photographs)
        renders.frames.prepare()
    executor = executor_from_args(args)
    check_not_sharded(args, executor.sharded)
    settings = settings_from_args(args)
    memory = memory_given(args)
    stream_level(args)   # --lod-level: with --memory and a Streamed SOG or LCC
    if memory is not None and executor.sharded:
        raise SplatglError("--memory streams the views in one process, not with --workers or "
                           "--executor ray")
    keep = args.worst if args.sheet is not None else 0
    run = None
    if executor.sharded:   # the workers load the scene; this process only merges
        from ..measure.evaluation.evaluate_tasks import evaluate_sharded

        result, worst, run = evaluate_sharded(args.scene if args.scene is not None else demo_scene_path(),
                                              views, executor, settings, RendererKind(args.renderer),
                                              keep, args.drop_invalid, default_progress(), renders)
    else:
        streamed = streamed_frames(args, settings, memory) if memory is not None else None
        scene = load_scene_arg(args) if streamed is None else streamed.framing
        with Renderer() if streamed is None else streamed as renderer:
            result, worst = evaluate(renderer, scene, views, settings, RendererKind(args.renderer),
                                     keep, default_progress(), renders)
    text = sys.stderr if json_to_stdout(args) else sys.stdout   # stdout: the JSON alone
    if not json_to_stdout(args):
        print(result.table())
        if memory is not None:
            print(f"streaming: {streamed.summary()}")
            if getattr(streamed, "capped", None):   # said once: the memory bound's cut
                print(streamed.capped)
        if run is not None:
            print(summary(run, "views"))
    with outputs:
        if args.csv is not None:
            atomic_write_text(outputs.temp("--csv"), result.csv())
        if json_file is not None:
            atomic_write_text(outputs.temp("--json"), result.json())
        if args.sheet is not None:
            write_image(outputs.temp("--sheet"), worst_sheet(worst))
    if json_to_stdout(args):
        emit_json(args, result.json())
    if args.csv is not None:
        print(f"wrote {args.csv}", file=text)
    if json_file is not None:
        print(f"wrote {json_file}")
    if args.sheet is not None:
        print(f"wrote {args.sheet} ({len(worst)} worst views)", file=text)
    if renders is not None:
        print(f"wrote {len(views)} renders to {renders.folder}", file=text)
    return 0


def _dataset_files(dataset: Path, views) -> list[Path]:
    """The files of ``dataset`` eval reads, which no output may be: each view's photograph and
    the camera files (the folder's own files, its ``sparse/*/`` models)."""
    files = [v.image for v in views if v.image is not None]
    dataset = Path(dataset)
    if dataset.is_file():
        return files + [dataset]
    sparse = dataset / "sparse"
    for folder in [dataset, sparse, *(sorted(sparse.iterdir()) if sparse.is_dir() else [])]:
        if folder.is_dir():
            files += [p for p in folder.iterdir() if p.is_file()]
    return files


def _render_files(args: argparse.Namespace) -> RenderFiles | None:
    """Where ``--renders`` writes (checked before any work); --layers/--format need it."""
    if args.renders is None:
        given = [o for o, v in (("--layers", args.layers), ("--format", args.format)) if v is not None]
        if args.normal_space != "camera":
            given.append("--normal-space")
        if given:
            raise SplatglError(f"{', '.join(given)} describe the renders eval writes; give --renders DIR")
        return None
    if args.renders.exists() and not args.renders.is_dir():
        raise SplatglError(f"--renders {args.renders}: exists and is not a folder")
    layer_files(args, None)   # --layers and --normal-space checked
    frames = FrameTarget.parse(f"{args.renders}/", args.format).with_layers(
        named_layers(args), args.normal_space)
    return RenderFiles(args.renders, frames)
