"""``--memory SIZE``: the one option (and default) bounding a command's peak memory, shared by
``lod``, ``edit``, ``convert`` and ``info`` (parsing and the default live in
:mod:`splatgl.lod.budget`: a fraction of this machine's RAM)."""

from __future__ import annotations

import argparse

from ..lod.budget import budget_from


def add_memory_argument(p: argparse.ArgumentParser, what: str) -> None:
    """Add ``--memory SIZE``; ``what``: how the command keeps within it (for the help)."""
    p.add_argument("--memory", default=None, metavar="SIZE",
                   help="peak memory, e.g. 200M or 4G (default: half this machine's RAM); "
                        + what)


def memory_budget(args: argparse.Namespace) -> int:
    """Bytes of ``--memory`` (its default when not given)."""
    return budget_from(getattr(args, "memory", None))[0]


#: ``--memory``'s help on render, view, eval and bench (issue 41 item 3).
STREAM_HELP = ("stream a level of detail (SCENE from 'splatgl lod') from disk, holding at most "
               "SIZE of its nodes resident: chunks of nodes are read on background threads as "
               "the cut needs them, the least recently used evicted; implies the level of "
               "detail's default cut where no --lod-* option is given")


def memory_given(args: argparse.Namespace) -> int | None:
    """Bytes of ``--memory`` where it was given, else None (render, view: not streamed)."""
    value = getattr(args, "memory", None)
    return None if value is None else budget_from(value)[0]


def stream_inputs(args: argparse.Namespace, settings):
    """``(framing scene, camera)`` of a streamed render: the camera framed by the level of
    detail's proxy (:func:`splatgl.lod.stream_frames.framing_scene`), never the whole file."""
    from ..lod.lazy import LazyLod
    from ..lod.stream_frames import framing_scene
    from ._common import camera_from_args

    camera_from_args(args, None, settings)   # the camera file and options checked first
    with LazyLod(args.scene) as lazy:
        framing = framing_scene(lazy)
    return framing, camera_from_args(args, framing, settings)


def streamed_frames(args: argparse.Namespace, settings, memory: int):
    """``eval``/``bench --memory``: :class:`splatgl.lod.stream_frames.StreamFrames` of the
    ``.lod.ply`` SCENE under ``memory`` bytes, the cut its ``--lod-*`` options ask for (the
    defaults where the command has none); a scene not from ``splatgl lod``, or another renderer
    than the quad path, is one line."""
    from ..errors import SplatglError
    from ..lod.io import is_lod_file
    from ..lod.selection import LodSettings
    from ..lod.stream_frames import StreamFrames

    renderer = getattr(args, "renderer", "quad")
    if renderer not in ("quad", "auto"):   # auto: a level of detail draws through the quad path
        raise SplatglError(f"--memory streams a level of detail through the quad path, not "
                           f"--renderer {renderer}")
    scene = getattr(args, "scene", None)
    if scene is None or not is_lod_file(scene):
        raise SplatglError(f"{scene}: not a level-of-detail file (--memory streams one); build "
                           "one with 'splatgl lod SCENE -o SCENE.lod.ply'")
    given = {name: getattr(args, option) for name, option in (
        ("threshold_px", "lod_threshold"), ("budget", "lod_budget"), ("band", "lod_blend"))
        if getattr(args, option, None) is not None}
    return StreamFrames(scene, settings, LodSettings(**given), memory)


def run_stream_bench(args: argparse.Namespace, sharded: bool, modes: list[str]) -> int:
    """``splatgl bench SCENE.lod.ply --memory SIZE``: :func:`splatgl.measure.bench.stream_bench.run_stream`
    (its figures printed, or as JSON with --json); ``modes``: the other benchmarks' flags given
    (:func:`._bench_modes.modes_given`), refused."""
    from ..measure.bench.stream_bench import describe, run_stream
    from ..errors import SplatglError
    from ..lod.io import is_lod_file
    from ._json_output import emit_json, json_to_stdout

    others = modes + [m for m, on in (("--out", args.out), ("--workers/--executor ray", sharded))
                      if on]
    if others:
        raise SplatglError(f"--memory streams one level of detail in one process; not with "
                           f"{', '.join(others)}")
    if len(args.scenes) != 1 or not is_lod_file(args.scenes[0]):
        raise SplatglError("--memory: give one level-of-detail file (from 'splatgl lod') to "
                           f"stream, got {', '.join(map(str, args.scenes)) or 'none'}")
    quick = args.quick
    memory = memory_given(args)
    report = run_stream(args.scenes[0], memory, args.width or (160 if quick else 1280),
                        args.height or (120 if quick else 720), args.frames or (4 if quick else 12))
    if not json_to_stdout(args):
        print(describe(report))
    if args.json is not None:
        emit_json(args, report)
    return 0
