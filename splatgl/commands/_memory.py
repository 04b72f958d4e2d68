"""``--memory SIZE``: the one option (and default) bounding a command's peak memory, shared by
``lod``, ``edit``, ``convert`` and ``info`` (parsing and the default live in
:mod:`splatgl.lod.budget`: a fraction of this machine's RAM)."""

from __future__ import annotations

import argparse
from pathlib import Path

from ..lod.budget import budget_from


def add_memory_argument(p: argparse.ArgumentParser, what: str) -> None:
    """Add ``--memory SIZE``; ``what``: how the command keeps within it (for the help)."""
    p.add_argument("--memory", default=None, metavar="SIZE",
                   help="peak memory, e.g. 200M or 4G (default: half this machine's RAM); "
                        + what)


def memory_budget(args: argparse.Namespace) -> int:
    """Bytes of ``--memory`` (its default when not given)."""
    return budget_from(getattr(args, "memory", None))[0]


#: ``--memory``'s help on render, view, eval and bench (issue 41 items 3 and 4).
STREAM_HELP = ("stream a level of detail (SCENE from 'splatgl lod', or a Streamed SOG "
               "lod-meta.json or LCC meta.lcc) from disk, holding at most SIZE of it resident: "
               "chunks are read on background threads as the view needs them, the least "
               "recently used evicted; implies the default cut (a Streamed SOG's or LCC's: each "
               "chunk's coarsest level within 1 px of screen-space error) where no --lod-* "
               "option is given")
#: ``--lod-level``'s help (the same commands).
LEVEL_HELP = ("with --memory and a Streamed SOG (lod-meta.json) or LCC (meta.lcc) SCENE: draw "
              "every chunk in view at level N (0 the finest; 'splatgl info SCENE' lists the "
              "levels and their splats) instead of choosing each chunk's level by its "
              "screen-space error")


def add_level_argument(p: argparse.ArgumentParser) -> None:
    """Add ``--lod-level N`` (:data:`LEVEL_HELP`)."""
    from ._common import non_negative_int

    p.add_argument("--lod-level", type=non_negative_int, default=None, metavar="N",
                   help=LEVEL_HELP)


def is_chunked_scene(args: argparse.Namespace) -> bool:
    """Whether SCENE is a Streamed SOG or an LCC scene (streamed by levels per chunk)."""
    from ..lod.stream_levels import is_chunked

    return getattr(args, "scene", None) is not None and is_chunked(args.scene)


def _cut_options(args: argparse.Namespace) -> dict:
    """The --lod-threshold/--lod-budget/--lod-blend given, as LodSettings fields."""
    return {name: getattr(args, option) for name, option in (
        ("threshold_px", "lod_threshold"), ("budget", "lod_budget"), ("band", "lod_blend"))
        if getattr(args, option, None) is not None}


#: The options that read SCENE as a level of detail (render, view, eval, bench).
LOD_OPTIONS = ("memory", "lod_level", "lod_threshold", "lod_budget", "lod_blend")


def check_scene_file(path) -> None:
    """SCENE read as :func:`splatgl.load_scene` reads it first
    (:func:`splatgl.formats.detect_format`): a missing file is ``PATH: no such file`` (a
    folder, an unreadable or an unknown file its own line), as ``info`` and a plain render say,
    before a level-of-detail check asks what kind of file it is (before, a missing
    ``x.lod.ply`` was 'not a level-of-detail file'); None, the bundled demo, passes."""
    from ..formats import detect_format

    if path is not None:
        detect_format(Path(path))


def stream_level(args: argparse.Namespace) -> int | None:
    """``--lod-level`` where given, checked before any work (one line each): with --memory, a
    Streamed SOG or LCC SCENE holding that level, no other --lod-* option.  The first check of
    every command's level-of-detail options: where any of :data:`LOD_OPTIONS` is given, SCENE
    must be a file (:func:`check_scene_file`)."""
    from ..errors import SplatglError
    from ..lod.stream_levels import check_level, read_structure

    if any(getattr(args, name, None) is not None for name in LOD_OPTIONS):
        check_scene_file(getattr(args, "scene", None))
    level = getattr(args, "lod_level", None)
    if level is None:
        return None
    if getattr(args, "memory", None) is None:
        raise SplatglError(f"--lod-level {level} draws a level of a Streamed SOG or LCC streamed "
                           "from disk: add --memory SIZE")
    if not is_chunked_scene(args):
        raise SplatglError(f"--lod-level: {getattr(args, 'scene', None)} is not a Streamed SOG "
                           "(lod-meta.json) or LCC (meta.lcc); a .lod.ply's cut is chosen by "
                           "--lod-threshold/--lod-budget")
    if _cut_options(args):
        raise SplatglError("--lod-level draws every chunk at one level; not with "
                           "--lod-threshold, --lod-budget or --lod-blend")
    check_level(read_structure(args.scene), level)
    return level


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
    if is_chunked_scene(args):   # a Streamed SOG or LCC: its chunks' boxes
        from ..lod.stream_levels import framing_at

        return (framing := framing_at(args.scene)), camera_from_args(args, framing, settings)
    with LazyLod(args.scene) as lazy:
        framing = framing_scene(lazy)
    return framing, camera_from_args(args, framing, settings)


def streamed_frames(args: argparse.Namespace, settings, memory: int, framing=None):
    """``render --path``/``eval``/``bench --memory``: the frames of SCENE streamed under
    ``memory`` bytes (:class:`splatgl.lod.stream_frames.StreamFrames` of a ``.lod.ply``,
    :class:`splatgl.lod.stream_levels.ChunkedFrames` of a Streamed SOG or LCC), the cut its
    ``--lod-*`` options ask for (the defaults where the command has none); ``framing``: what
    frames the views, where already read; drawn by :func:`stream_renderer`'s choice.  A scene
    of neither kind, or another renderer than the quad path or the CPU renderer, is one line."""
    from ..lod.selection import LodSettings
    from ..lod.stream_frames import StreamFrames
    from ..lod.stream_levels import ChunkedFrames

    scene = getattr(args, "scene", None)
    check_streamable(args)
    kind = stream_renderer(args, settings, framing)
    level = stream_level(args)
    lod = LodSettings(**_cut_options(args))
    if is_chunked_scene(args):
        return ChunkedFrames(scene, settings, lod, memory, level, kind, framing=framing)
    return StreamFrames(scene, settings, lod, memory, framing=framing, kind=kind)


def stream_renderer(args: argparse.Namespace, settings, framing=None, camera=None, layers=None,
                    under=None):
    """The renderer a streamed frame draws with (issue 40 item 4 for streamed frames):
    ``--renderer quad`` or ``cpu`` as given (checked against the request), ``auto`` resolved as
    for an in-memory render (:func:`splatgl.commands._renderer_auto.choose_renderer`: the CPU
    renderer on a software device where it can draw the request and its kernels are ready, said
    once where only they were missing); any other renderer is one line.  Sets ``args.renderer``
    to the choice (a second call keeps it)."""
    from ..lod.stream_frames import streamed_kind
    from ..renderers.registry import check
    from ._renderer_auto import AUTO, choose_renderer

    if getattr(args, "renderer", "quad") == AUTO:
        return streamed_kind(choose_renderer(args, framing, settings, camera, layers, under))
    kind = streamed_kind(getattr(args, "renderer", "quad"))
    check(kind, scene=framing, settings=settings,
          model=camera.model if camera is not None else None,
          layers=frozenset(layers) if layers is not None else None, under=under is not None)
    args.renderer = kind.value
    return kind


def check_streamable(args: argparse.Namespace) -> None:
    """SCENE is what ``--memory`` streams: a ``.lod.ply``, a Streamed SOG or an LCC scene (and
    a Streamed SOG or LCC is not given --lod-blend: a chunk switches its level whole)."""
    from ..errors import SplatglError
    from ..lod.io import is_lod_file

    scene = getattr(args, "scene", None)
    if is_chunked_scene(args):
        if getattr(args, "lod_blend", None) is not None:
            raise SplatglError(f"--lod-blend: {scene} switches a chunk's level whole (Streamed "
                               "SOG, LCC); drop --lod-blend")
        return
    if scene is None or not is_lod_file(scene):
        raise SplatglError(f"{scene}: not a level-of-detail file (--memory streams one: a "
                           ".lod.ply, a Streamed SOG lod-meta.json or an LCC meta.lcc); build "
                           "one with 'splatgl lod SCENE -o SCENE.lod.ply'")


def render_one_streamed(args: argparse.Namespace, camera, settings, lod, memory: int, layers,
                        under, framing):
    """``render --memory``'s one view: (the layers, times, the GL renderer's name) of SCENE
    streamed under ``memory`` bytes (:func:`splatgl.lod.stream_frames.render_streamed`, or
    :func:`splatgl.lod.stream_levels.render_chunked` for a Streamed SOG or LCC), drawn by
    :func:`stream_renderer`'s choice."""
    kind = stream_renderer(args, settings, framing, camera, layers, under)
    if is_chunked_scene(args):
        from ..lod.stream_levels import render_chunked

        return render_chunked(args.scene, camera, settings, lod, memory, stream_level(args),
                              layers, under, framing, kind)
    from ..lod.stream_frames import render_streamed

    return render_streamed(args.scene, camera, settings, lod, memory, layers, under, framing,
                           kind=kind)

