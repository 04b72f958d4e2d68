"""``splatgl lod SCENE -o SCENE.lod.ply``: build the level-of-detail hierarchy of a scene."""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from ..errors import SplatglError
from ..edit.decimate import plural
from ..formats import load_scene
from ..progress import StderrProgress, enabled
from ..scene.splats import SplatKind
from ._memory import add_memory_argument
from ._outputs import add_force_argument, check_output

NAME = "lod"
ORDER = 27
HELP = ("build a level-of-detail hierarchy (.lod.ply) for rendering with --lod-threshold/--lod-budget, "
        "or as PlayCanvas Streamed SOG (DIR/lod-meta.json)")
DESCRIPTION = """Build a scene's level-of-detail hierarchy offline: neighbouring splats (in Morton
order of their centres) are merged bottom-up, BRANCHING at a time, into parents whose mean,
covariance, opacity and SH match their children's moments (weighted by opacity x area, as in
the hierarchical 3DGS of Kerbl et al. 2024), up to one root.

The output is a PLY whose 'vertex' element holds the original splats (so any reader sees the
full-detail scene) and whose 'lod_node' element holds the merged parents.  Render it with
'splatgl render OUT --lod-threshold PX' (each view draws the coarsest nodes whose bounding
sphere projects to at most PX pixels) or '--lod-budget N' (the finest cut of at most N nodes).

examples:
  splatgl lod scene.ply -o scene.lod.ply
  splatgl render scene.lod.ply --lod-threshold 1 -o far.png --distance 4
  splatgl render scene.lod.ply --lod-budget 200000 -o view.png --timings

A binary PLY is built within --memory SIZE (default half this machine's RAM): read by blocks,
sorted on disk (temporary files beside the output, removed on any exit), the hierarchy built in
spatial chunks of whole subtrees, into the same file as in memory (docs/scale.md).  Other formats
are read whole.

Naming the output DIR/lod-meta.json writes PlayCanvas Streamed SOG instead (what splat-transform
writes and PlayCanvas streams): the hierarchy's finest levels as SOG folders DIR/L_i/, in spatial
chunks of --chunk-splats original splats, listed in lod-meta.json (see docs/formats.md); it is
built in memory, refused before the build where a binary PLY needs more than --memory.

  splatgl lod scene.ply -o out/lod-meta.json"""


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("scene", type=Path, help="scene file (any supported format; 3DGS)")
    p.add_argument("-o", "--output", type=Path, default=None,
                   help="output .lod.ply (default: SCENE's name with .lod.ply)")
    p.add_argument("--branching", type=int, default=4, metavar="B",
                   help="children per parent (default 4; 2-64)")
    p.add_argument("--chunk-splats", type=int, default=None, metavar="N",
                   help="Streamed SOG output (-o DIR/lod-meta.json): original splats per streamed "
                        "chunk, at least (default 16384)")
    add_memory_argument(p, "the build from a binary PLY keeps within it (the budget is "
                           "printed): larger scenes are built in spatial chunks from temporary "
                           "files beside the output")
    add_force_argument(p)


def default_output(scene: Path) -> Path:
    name = scene.name
    for suffix in (".compressed.ply", ".ply", ".spz", ".ksplat", ".splat"):
        if name.lower().endswith(suffix):
            name = name[: -len(suffix)]
            break
    return scene.with_name(name + ".lod.ply")


def run(args: argparse.Namespace) -> int:
    from ..lod.build import build_hierarchy
    from ..lod.io import check_lod_name, write_lod
    from ..lod import streamed_sog_write as streamed
    from ..lod.budget import budget_from, plan
    from ..lod.external import build_lod_file
    from ..lod.ply_rows import streamable

    if not 2 <= args.branching <= 64:
        raise SplatglError(f"--branching must be 2-64, got {args.branching}")
    out = args.output or default_output(args.scene)
    sog = streamed.is_streamed_sog_name(out)
    if not sog:
        check_lod_name(out)
        if args.chunk_splats is not None:
            raise SplatglError("--chunk-splats applies to Streamed SOG output (-o "
                               "DIR/lod-meta.json) only")
    elif args.chunk_splats is not None and args.chunk_splats < 1:
        raise SplatglError(f"--chunk-splats must be at least 1, got {args.chunk_splats}")
    check_output(args, out, "-o")  # before the (long) build: not SCENE; existing only with --force
    if sog:
        streamed.check_folder(out)  # no unit folder the manifest there does not name
    budget, how = budget_from(args.memory)
    if sog:   # built in memory: refused over the budget, as convert refuses formats written whole
        from ..edit.streamed import sources_of
        from ..lod.budget import format_size

        sources = sources_of([args.scene])   # a binary PLY: its decoded size from the header
        need = None if sources is None else streamed.BUILD_COPIES * sources[0].in_memory_bytes()
        if need is not None and need > budget:
            raise SplatglError(f"{out}: a Streamed SOG is built from the whole scene in memory "
                               f"(about {format_size(need)}, over --memory {format_size(budget)});"
                               " write a .lod.ply, which builds within it, or give a larger "
                               "--memory")
    progress = StderrProgress() if enabled() else None
    if not sog and streamable(args.scene):
        if progress is not None:  # on a terminal; the summary below says it too
            print(f"lod: memory budget {how}", file=sys.stderr)
        t0 = time.perf_counter()
        info = build_lod_file(args.scene, out, args.branching,
                              lambda record, count: plan(budget, args.branching, record, count),
                              progress)
        print(f"wrote {out}: {info['leaves']:,} leaves, {info['parents']:,} parents in "
              f"{info['levels']} levels (branching {args.branching}) in "
              f"{time.perf_counter() - t0:.1f} s ({plural(info['chunks'], 'chunk')} of at most "
              f"{info['window']:,} leaves; memory budget {how})")
        return 0
    scene = load_scene(args.scene, progress=progress)
    if scene.kind is not SplatKind.GAUSSIAN_3D:
        raise SplatglError(f"{args.scene}: level of detail needs 3DGS splats, this file holds 2DGS surfels")
    t0 = time.perf_counter()
    tree = build_hierarchy(scene, args.branching, progress=progress)
    if sog:
        meta = streamed.write_streamed_sog(out, tree, args.chunk_splats or streamed.CHUNK_SPLATS)
        counts = ", ".join(f"{c:,}" for c in meta["counts"])
        print(f"wrote {out}: Streamed SOG of {meta['lodLevels']} levels ({counts} splats) in "
              f"{len(meta['filenames'])} SOG units (branching {args.branching}) in "
              f"{time.perf_counter() - t0:.1f} s")
        return 0
    write_lod(out, tree)
    whole = (f" ({args.scene.name} was read whole: --memory bounds the build from a binary PLY)"
             if args.memory is not None else "")
    print(f"wrote {out}: {scene.count:,} leaves, {tree.nodes.count - scene.count:,} parents in "
          f"{tree.levels} levels (branching {args.branching}) in {time.perf_counter() - t0:.1f} s"
          + whole)
    return 0
