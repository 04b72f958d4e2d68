"""``splatgl render --path SOURCE``: many frames in one process (options and the run).

Kept apart from :mod:`splatgl.commands.render` so the single-view command stays small; the
work itself is :func:`splatgl.tasks.batch.render_frames`.
"""

from __future__ import annotations

import argparse

from ..tasks.batch import render_frames
from ..tasks.render_tasks import stopped_note
from ..cameras.camera import Camera
from ..datasets import load_source, select_indices
from ..errors import SplatglError, add_note
from ..tasks.executor import summary
from ._executor import add_executor_arguments, executor_from_args
from ._frame_budget import add_target_fps_argument
from ..imagefiles.layer_files import check_exact_ids
from ..output.layers import BASE
from ..imagefiles.frame_record import FrameRecord, options_digest, recorded_renderer, scene_digest
from ._layers import check_under_options, layer_files, named_layers
from ..imagefiles.frame_targets import FrameTarget
from ..imagefiles.image_formats import FORMAT_NAMES
from ..gl.context import renderer_name
from ..paths import orbit
from ..progress import default_progress
from ..api import Renderer, gl_renderer_name
from ..scene.splats import Scene
from ..cameras.up import resolve_up
from ..cameras.orthographic import Orthographic
from ..cameras.pinhole import Pinhole
from ..cameras.registry import adapt_camera, retarget
from ..interactive.budget import check_fps
from ..interactive.preview import PreviewRenderer
from ..lod.frames import LodFrames
from ..lod.io import framed_leaves, is_lod_file, read_lod
from ..lod.budget import format_size
from ..lod.selection import LodSettings
from ..scene.settings import RendererKind
from ..renderers.auto import Choice
from ..renderers.registry import check
from ._renderer_auto import AUTO, auto_lines, choose_renderer
from ..renderers.stereo import StereoLayout, StereoRenderer
from ._common import (check_convention, default_size, demo_scene_path, load_scene_arg,
                      positive_float, projection_from_args, settings_from_args)
from ._spz_axes import check_not_sharded
from ._memory import (check_streamable, is_chunked_scene, memory_given, stream_inputs,
                      stream_level, stream_renderer, streamed_frames)
from ._outputs import check_outputs

DEFAULT_FPS = 30.0
DEFAULT_ORBIT_FRAMES = 120


def add_path_arguments(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group("many frames (camera paths, datasets, video)")
    g.add_argument("--path", default=None, metavar="SOURCE",
                   help="render every camera of SOURCE instead of one view: a COLMAP model (or "
                        "dataset folder), transforms.json, 3DGS cameras.json, nerfstudio "
                        "camera_path.json, a splatgl path file (splatgl path ...), or 'orbit[:N]' "
                        "(N frames around the scene, default 120). -o is then a folder, a "
                        "pattern such as frames/%%05d.png or .exr, or a video .mp4")
    g.add_argument("--select", default=None, metavar="RANGES",
                   help="only these cameras of SOURCE: start:stop:step and/or indices, "
                        "comma-separated (e.g. 0:100:5 or 0,3,7)")
    g.add_argument("--resume", action="store_true",
                   help="skip frames whose files already exist (frames are written atomically, "
                        "so an existing file is complete); for a video with --workers or "
                        "--executor ray, the frames kept from a stopped run. Each frame records "
                        "the path, camera, scene and options it was rendered from: frames of "
                        "another are refused")
    g.add_argument("--format", default=None, choices=FORMAT_NAMES,
                   help="image format when -o is a folder (default png; refused with a video or "
                        "a pattern, whose suffix says it)")
    g.add_argument("--fps", type=positive_float, default=None,
                   help="video frame rate (default: the path file's, else 30)")
    g.add_argument("--preview", action="store_true",
                   help="a quick draft of the path: every frame drawn as the viewer draws a moving "
                        "camera, within a frame-time budget (a lower render scale, a level-of-detail "
                        "cut and SH degree as needed, upscaled to full size); the levels used are "
                        "printed. For checking a path before the exact render")
    add_target_fps_argument(g, "--preview's frame-time budget in frames a second")
    executor = add_executor_arguments(p, "contiguous chunks of the path (a video is encoded here "
                                         "once every frame exists; its frames wait in "
                                         ".NAME.mp4.frames/, kept for --resume if the run stops)",
                                      "Ray tasks of up to 32 frames")
    # What only --path uses, with its defaults: given without --path, it is refused.
    p.set_defaults(_path_only=[(a.option_strings[0], a.dest, a.default)
                               for a in g._group_actions[1:] + executor._group_actions])


def lod_settings_from_args(args: argparse.Namespace) -> LodSettings | None:
    """The cut ``--lod-threshold/--lod-budget/--lod-blend`` ask for (None: no option given; the
    others :class:`~splatgl.lod.selection.LodSettings`' defaults), checked before any work: the
    quad renderer, a ``.lod.ply`` scene, valid values."""
    given = {name: value for name, value in (("threshold_px", args.lod_threshold),
                                             ("budget", args.lod_budget), ("band", args.lod_blend))
             if value is not None}
    stream_level(args)   # --lod-level: with --memory and a Streamed SOG or LCC
    if not given and getattr(args, "memory", None) is None:
        return None
    streamed = getattr(args, "memory", None) is not None
    if args.renderer not in ("quad", AUTO) + (("cpu",) if streamed else ()):
        raise SplatglError(f"--lod-threshold/--lod-budget render through the quad path (--memory: "
                           f"the quad path or the cpu renderer), not --renderer {args.renderer}")
    if getattr(args, "memory", None) is not None:   # a .lod.ply, a Streamed SOG or an LCC
        check_streamable(args)
    elif is_chunked_scene(args):
        raise SplatglError(f"{args.scene}: --lod-threshold/--lod-budget/--lod-blend choose a "
                           "Streamed SOG's or LCC's levels when it streams: add --memory SIZE")
    elif args.scene is None or not is_lod_file(args.scene):
        options = [o for o, v in (("--lod-threshold", args.lod_threshold), ("--lod-budget", args.lod_budget),
                                  ("--lod-blend", args.lod_blend), ("--memory", getattr(args, "memory", None)))
                   if v is not None]
        scene = args.scene if args.scene is not None else f"the bundled demo {demo_scene_path().name}"
        raise SplatglError(f"{scene}: not a level-of-detail file, which {', '.join(options)} "
                           f"{'read' if len(options) > 1 else 'reads'}; build one with "
                           "'splatgl lod SCENE -o SCENE.lod.ply'")
    return LodSettings(**given)


def check_preview(args: argparse.Namespace, target: FrameTarget, sharded: bool,
                  lod: LodSettings | None) -> None:
    """Refuse, before any work, what ``--preview`` cannot combine with (one line each)."""
    check_fps(args.target_fps)
    refusals = (
        (args.renderer not in ("quad", AUTO), f"--preview draws through the quad path, not --renderer {args.renderer}"),
        (sharded, "--preview renders in one process (not with --workers or --executor ray)"),
        (args.stereo is not None, "--preview and --stereo cannot be combined"),
        (lod is not None, "--preview chooses its own level-of-detail cut; drop --lod-threshold/"
                          "--lod-budget/--lod-blend"),
        (args.resume, "--preview frames are drafts: --resume would mix them with exact frames"),
    )
    for refused, message in refusals:
        if refused:
            raise SplatglError(message)
    undrawn = sorted(layer.value for layer in (target.layers or BASE) - BASE)
    if undrawn and target.named:
        raise SplatglError(f"--preview draws colour and alpha only, not --layers {', '.join(undrawn)} "
                           "(render the path without --preview for them)")
    if undrawn:      # an .exr pattern's own layers: its Z channel
        raise SplatglError(f"{args.output}: EXR frames carry Z (the depth layer), which --preview "
                           "does not draw; give --layers colour,alpha for EXR drafts without Z, or "
                           "use a .png pattern, a folder or a video")


def refuse_path_only_options(args: argparse.Namespace) -> None:
    """One line naming the options that only --path uses, when given without it."""
    given = [opt for opt, dest, default in getattr(args, "_path_only", ())
             if getattr(args, dest) != default]
    if given:
        verb = "applies" if len(given) == 1 else "apply"
        raise SplatglError(f"{', '.join(given)} {verb} to --path only (many frames); without "
                           "--path, render draws one view")


def path_cameras(args: argparse.Namespace, scene: Scene) -> tuple[list[Camera], float | None, list[int]]:
    """The cameras ``--path`` names (with ``--select``, ``--width/--height``, ``--projection``
    and ``--fov`` applied as to a ``--camera`` file: :func:`splatgl.cameras.registry.adapt_camera`), the
    source's frame rate (None if it has none) and each camera's index in the source (its frame
    number)."""
    spec = args.path
    projection = projection_from_args(args)
    is_orbit = spec == "orbit" or spec.startswith("orbit:")
    if is_orbit:
        try:
            frames = int(spec.split(":", 1)[1]) if ":" in spec else DEFAULT_ORBIT_FRAMES
        except ValueError:
            raise SplatglError(f"--path {spec}: expected orbit or orbit:FRAMES") from None
        if frames < 1:
            raise SplatglError(f"--path {spec}: the number of frames must be positive")
        w, h = default_size(args, projection)
        lens = projection not in (None, Pinhole.name, Orthographic.name)  # its own --fov, if any
        up, _ = resolve_up(args.up, args.scene, None)   # as the default camera's (frame 0)
        cams = orbit(scene, frames, w, h, args.fov if args.fov is not None and not lens else 50.0,
                     up=tuple(float(v) for v in up))
        if projection:
            cams = [retarget(c, projection, args.fov if lens else None) for c in cams]
        fps = None
    else:
        views, fps = load_source(spec)
        cams = [v.camera for v in views]
    numbers = list(range(len(cams)))
    if args.select:
        numbers = select_indices(args.select, len(cams), spec)
    cams = [cams[i] for i in numbers]
    if not is_orbit:
        if args.up is not None:
            raise SplatglError(f"--up places the default camera and orbit paths; --path {spec} "
                               "brings its own cameras")
        cams = [adapt_camera(c, args.width, args.height, projection, args.fov, f"{spec} (camera {i})")
                for i, c in zip(numbers, cams)]
    return cams, fps, numbers


def check_frame_outputs(args: argparse.Namespace, target: FrameTarget, numbers) -> None:
    """Every file the frames (and their layer pictures) or the video go to, before any frame
    renders: none is a file this command reads, and one that exists is replaced only with
    --force (--resume keeps complete frames and renders damaged ones again: no overwrite)."""
    paths = [target.video] if target.is_video else [p for n in numbers for p in target.frame_paths(n)]
    check_outputs(args, paths, "-o", keep=args.resume)


def frame_record(args: argparse.Namespace, scene: Scene, settings, target: FrameTarget,
                 kind: RendererKind, lod: LodSettings | None) -> FrameRecord:
    """What this run's frames are rendered from (:mod:`splatgl.imagefiles.frame_record`): written
    into every frame, and checked by --resume against the frames it keeps."""
    layers = sorted(layer.value for layer in (target.layers or BASE))
    options = options_digest(settings=repr(settings), renderer=kind.value, bit_depth=args.bit_depth,
                             layers=layers, named=[layer.value for layer in target.named],
                             normal_space=target.normal_space.value, lod=repr(lod),
                             stereo=[args.stereo, args.stereo_layout] if args.stereo is not None
                             else None, preview=bool(args.preview), video=target.is_video,
                             **({"lod_level": args.lod_level}
                                if getattr(args, "lod_level", None) is not None else {}))
    digest = getattr(scene, "digest", None)   # a streamed level of detail's (never read whole)
    return FrameRecord(args.path, digest if isinstance(digest, str) else scene_digest(scene), options,
                       kind.value)


def _resumed_renderer(args: argparse.Namespace, target: FrameTarget, numbers,
                      sharded: bool) -> Choice | None:
    """With ``--resume``: the renderer the frames already there record
    (:func:`~splatgl.imagefiles.frame_record.recorded_renderer`), which ``--renderer auto``
    takes (auto could choose another on this run: cpu once its kernels are compiled, else quad);
    a ``--renderer`` naming another is refused in one line.  None: no such frame."""
    if not args.resume:
        return None
    frames = target
    if target.is_video:         # a sharded video's frames wait in its hidden folder
        from ..tasks.render_tasks import frame_folder

        if not sharded:
            return None
        frames = FrameTarget.parse(f"{frame_folder(target.video)}/", "png")
    found = recorded_renderer(frames.frame_path(n) for n in numbers)
    if found is None:
        return None
    kind, frame = found
    if args.renderer not in (AUTO, kind):
        raise SplatglError(f"--renderer {args.renderer}: {frame} (--resume keeps it) was rendered "
                           f"by the {kind} renderer; leave --renderer out to complete the frames "
                           "with it, or render into another folder")
    return Choice(RendererKind(kind), f"the renderer of {frame}, kept by --resume")


def run_path(args: argparse.Namespace) -> int:
    if args.camera is not None:
        raise SplatglError("--camera and --path exclude each other (a path brings its cameras)")
    if args.distance is not None:
        raise SplatglError("--distance places the default camera; with --path it has no effect "
                           "(an orbit's radius: splatgl path orbit --radius)")
    if args.depth_png is not None:
        raise SplatglError("--depth-png renders one view; use -o frames/%05d.exr for depth per frame")
    if args.under is not None:
        raise SplatglError("--under composites one view into a render of its geometry; not with --path")
    target = FrameTarget.parse(args.output, args.format).with_layers(named_layers(args),
                                                                     args.normal_space)
    layer_files(args, None)     # --normal-space world needs the normal layer
    check_under_options(args)
    check_convention(args, RendererKind(args.renderer if args.renderer != AUTO else "quad"))
    executor = executor_from_args(args)
    check_not_sharded(args, executor.sharded)
    if args.stereo is not None and executor.sharded:
        raise SplatglError("--stereo renders paths in one process (not with --workers or --executor ray)")
    lod = lod_settings_from_args(args)
    if lod is not None and args.stereo is not None:
        raise SplatglError(LodFrames.stereo_refusal)
    if args.resume and target.is_video and not executor.sharded:
        raise SplatglError(f"{args.output}: a video rendered in one process cannot be resumed; "
                           "render it with --workers N or --executor ray (their frames are kept "
                           "until the video is assembled)")
    if args.preview:
        check_preview(args, target, executor.sharded, lod)
    elif args.target_fps is not None:
        raise SplatglError("--target-fps is the budget of --preview; without --preview every "
                           "frame is exact")
    memory = memory_given(args)
    if memory is not None and (executor.sharded or args.preview):
        raise SplatglError("--memory streams a path's frames in one process, not with "
                           "--workers, --executor ray or --preview")
    tree = read_lod(args.scene, default_progress()) if lod is not None and memory is None else None
    settings = settings_from_args(args)
    if memory is not None:   # streamed: the box the file records frames the orbit
        scene, _ = stream_inputs(args, settings)
    else:  # the scene frames the orbit and is counted in the summary: a LOD file's leaves
        scene = (load_scene_arg(args) if tree is None else   # framed as load_scene frames it
                 framed_leaves(tree, args.scene))
    if not target.is_video:
        check_exact_ids(target.files(), target.frame_path(0), scene.count)
        if args.fps is not None:   # refused, never ignored
            raise SplatglError(f"--fps sets a video's frame rate; -o {args.output} writes image "
                               "files, which hold none (give a .mp4 or .mov to write a video)")
    cameras, source_fps, numbers = path_cameras(args, scene)
    check_frame_outputs(args, target, numbers)
    fps = args.fps if args.fps is not None else (source_fps or DEFAULT_FPS)
    if not fps > 0:
        raise SplatglError(f"--fps must be positive, got {fps}")
    kept = _resumed_renderer(args, target, numbers, executor.sharded)
    if kept is not None and args.renderer == AUTO:   # --resume: the renderer of the frames kept
        args.renderer, args.renderer_choice = kept.kind.value, kept
    elif args.renderer == AUTO and lod is None and memory is None and not args.preview:
        choose_renderer(args, scene, settings, cameras[0], target.layers or None, None)
    elif memory is not None:          # streamed: auto as above, the quad path or the cpu renderer
        stream_renderer(args, settings, scene, cameras[0], target.layers or None, None)
    elif args.renderer == AUTO:       # a level of detail, drafts: the quad path's
        args.renderer = RendererKind.QUAD.value
    kind = RendererKind(args.renderer)
    record = frame_record(args, scene, settings, target, kind, lod)
    check(kind, scene=scene, settings=settings)     # before the output folder exists
    if kind is RendererKind.CPU and not executor.sharded:
        # the kernels (compiled on first use, half a minute) before the output folder exists
        # too: a Ctrl-C during the compile leaves nothing behind
        from ..renderers.cpu import prepare
        prepare()
    gl_name = "not known here (the frames were rendered by workers)"
    size = (cameras[0].width, cameras[0].height)
    try:
        result, run, gl_name, size, streamed = _render_all(
            args, scene, cameras, settings, target, executor, kind, fps, numbers, lod, record,
            memory, tree, gl_name, size)
    except (KeyboardInterrupt, SplatglError) as exc:   # say what is left, on the one line
        note = None if args.preview else stopped_note(target, numbers, executor.sharded,
                                                      isinstance(exc, KeyboardInterrupt))
        raise (exc if note is None else add_note(exc, note))
    where = target.video if target.is_video else target.pattern
    skipped = f", {result.skipped} already there" if result.skipped else ""
    if result.damaged:
        skipped += f", {result.damaged} damaged ones rendered again"
    if result.unchecked:
        skipped += (f", {result.unchecked} of them without a record of their path, scene and "
                    "options to check (older splatgl)")
    kind_text = f"{kind.value}, level of detail" if lod is not None else kind.value
    if memory is not None:
        kind_text += f" streamed under {format_size(memory)}"
    print(f"wrote {result.written} frames to {where}{skipped} ({size[0]}x{size[1]}, "
          f"{scene.count} splats, {kind_text}, {result.fps:.2f} frames/s)")
    if run is not None:
        print(summary(run, "frames"))
    if memory is not None and getattr(streamed, "capped", None):   # said once (and --timings)
        print(streamed.capped)
    if args.timings:
        print(f"GL renderer: {gl_name}")
        for line in auto_lines(args, settings, gl_name if not executor.sharded else None):
            print(line)
        ratio = result.seconds / result.render_seconds if result.render_seconds > 0 else float("nan")
        print(f"timings: {result.seconds:.3f} s for {result.written} frames; renderer stages "
              f"{result.render_seconds:.3f} s; ratio {ratio:.3f}")
        if memory is not None:
            print(f"streaming: {streamed.summary()}")
    return 0


def _render_all(args, scene, cameras, settings, target, executor, kind, fps, numbers, lod, record,
                memory, tree, gl_name, size):
    """Render the path's frames on the executor, as a preview, or here: (the result, the
    workers' run or None, the GL renderer's name, the frame size, the streamed frames or None)."""
    run = streamed = None
    if executor.sharded:
        from ..tasks.render_tasks import render_sharded

        result, run = render_sharded(args.scene if args.scene is not None else demo_scene_path(),
                                     cameras, settings, target, executor, kind, args.bit_depth,
                                     args.resume, args.drop_invalid, fps, default_progress(),
                                     numbers, lod, record)
    elif args.preview:
        with PreviewRenderer(args.target_fps, args.scene if args.scene is not None
                             else demo_scene_path()) as renderer:
            gl_name = renderer_name(renderer.ctx)
            result = render_frames(renderer, scene, cameras, settings, target, kind, args.bit_depth,
                                   False, fps, default_progress(), numbers=numbers, record=record)
        print(renderer.report())
    else:
        with (streamed_frames(args, settings, memory, scene) if memory is not None
              else Renderer() if tree is None else LodFrames(tree, settings, lod)) as renderer:
            streamed = renderer if memory is not None else None
            gl_name = gl_renderer_name(kind, renderer.ctx)
            if args.stereo is not None:    # each frame holds both eyes
                renderer = StereoRenderer(renderer, args.stereo, StereoLayout(args.stereo_layout))
                size = renderer.frame_size(cameras[0])
            result = render_frames(renderer, scene, cameras, settings, target, kind, args.bit_depth,
                                   args.resume, fps, default_progress(), numbers=numbers,
                                   record=record)
    return result, run, gl_name, size, streamed
