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

