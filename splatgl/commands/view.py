"""``splatgl view``: an interactive window (glfw, OpenGL 4.5 core) over the renderers."""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from ..cameras.camera_files import load_cameras
from ..cameras.up import resolve_up
from ..errors import SplatglError
from ..interactive.budget import check_fps
from ..scene.settings import RendererKind
from ..renderers.registry import check, names
from ..renderers import auto as renderer_auto
from ._renderer_auto import AUTO, auto_lines, choose_renderer
from ._common import (add_camera_arguments, add_scene_arguments, add_settings_arguments,
                      camera_from_args, check_convention, check_stereo_layout, demo_scene_path,
                      load_scene_arg, settings_from_args)
from ._frame_budget import add_target_fps_argument
from ._memory import (STREAM_HELP, add_level_argument, add_memory_argument, is_chunked_scene,
                      memory_given, stream_level)

NAME = "view"
ORDER = 15
HELP = "open an interactive window on a scene (default: the bundled demo)"
DESCRIPTION = """Look at a Gaussian-splat scene in a window (glfw; OpenGL 4.3+ needed, 4.5 asked for).

The splats are drawn by the same renderers as `splatgl render` into an offscreen float target
that is shown in the window; F12 writes the PNG `splatgl render` would write for the current
view, and the camera JSON (and the command line) that reproduces it.  Every rendering option of
`splatgl render` applies; the window starts at --width x --height (default 1280x720, or the
camera file's size scaled to fit 1600x1000).  Keys are printed at start (and with H).

examples:
  splatgl view
  splatgl view scene.ply --camera cameras.json --camera-index 5
  splatgl view scene.ply --precision rgba16f --background 1,1,1
  splatgl view scene.ply --benchmark 120      # scripted orbit, prints the frame rate"""

#: A camera file's image is shown in a window of at most this size (unless --width/--height).
MAX_WINDOW = (1600, 1000)


def add_arguments(p: argparse.ArgumentParser) -> None:
    add_scene_arguments(p)
    p.add_argument("--renderer", choices=[AUTO] + names(interactive=True),
                   default=AUTO, help="auto (default): the CPU renderer's exact frame on a "
                                        "machine without a GPU where it draws the scene and its "
                                        "compiled kernels are ready (compiled in the background "
                                        "on first use, quad meanwhile), else quad; or start "
                                        "with the quad path, the tile renderer or "
                                        "the CPU renderer (the fast extra; no OpenGL for the "
                                        "exact frame: while the camera moves, the quad path's "
                                        "drafts; at rest, the CPU renderer's exact frame, 2-3x "
                                        "sooner than the quad path's without a GPU)")
    p.add_argument("--screenshot-dir", type=Path, default=Path("."), metavar="DIR",
                   help="where F12 writes splatgl-view-NNNN.png/.json (default: here)")
    p.add_argument("--benchmark", type=int, default=None, metavar="FRAMES",
                   help="render FRAMES frames of a scripted orbit, print the frame rate and exit "
                        "(every frame exact unless --target-fps is given)")
    add_target_fps_argument(p, "frame-time budget while the camera moves: frames are drawn at "
                               "a lower render scale, a level-of-detail cut and a lower SH degree "
                               "as needed to reach F frames a second, then refined to the exact "
                               "image once the camera rests", zero="every frame exact")
    p.add_argument("--no-vsync", action="store_true", help="do not wait for the display refresh")
    add_memory_argument(p, STREAM_HELP + "; the window draws what is resident and refines as "
                           "chunks arrive, screenshots wait for theirs")
    add_level_argument(p)
    add_camera_arguments(p)
    add_settings_arguments(p)


def _fit(camera, max_size=MAX_WINDOW):
    """The camera scaled down (aspect kept) to fit a window of ``max_size``."""
    s = min(1.0, max_size[0] / camera.width, max_size[1] / camera.height)
    return camera if s >= 1.0 else camera.resized(max(1, round(camera.width * s)),
                                                  max(1, round(camera.height * s)))


def _render_args(args: argparse.Namespace) -> tuple[str, ...]:
    """``splatgl render`` arguments for what RenderSettings does not hold."""
    out = [str(args.scene if args.scene is not None else demo_scene_path())]
    if args.drop_invalid:
        out.append("--drop-invalid")
    if args.transform:
        out += ["--transform", args.transform]
    return tuple(out)


def run(args: argparse.Namespace) -> int:
    check_stereo_layout(args)   # none without --stereo; side-by-side by default
    if args.stereo is not None and args.stereo_layout != "side-by-side":
        raise SplatglError("the viewer shows stereo side by side; --stereo-layout is for render")
    if args.benchmark is not None and args.benchmark < 1:
        raise SplatglError(f"--benchmark needs at least 1 frame, got {args.benchmark}")
    check_convention(args, args.renderer if args.renderer != AUTO else "quad")
    # --benchmark times same-work frames (the peer race): exact unless a budget is asked for
    target_fps = check_fps(0.0 if args.benchmark is not None and args.target_fps is None
                           else args.target_fps)
    if args.screenshot_dir.exists() and not args.screenshot_dir.is_dir():
        raise SplatglError(f"--screenshot-dir {args.screenshot_dir}: is a file, not a folder")
    path = args.scene if args.scene is not None else demo_scene_path()
    memory = memory_given(args)
    stream_level(args)   # --lod-level: with --memory and a Streamed SOG or LCC
    stream = None
    t0 = time.perf_counter()
    if memory is not None:
        stream = _open_stream(args, memory)
        scene = stream.framing   # frames the views; each frame draws the resident cut
    else:
        print(f"loading {path} ...", flush=True)
        scene = load_scene_arg(args)
        print(f"loaded {scene.count:,} splats (SH degree {scene.sh_degree}) in "
              f"{time.perf_counter() - t0:.2f} s", flush=True)
    settings = settings_from_args(args)
    if args.renderer == AUTO:     # the exact frame at rest; moving frames are quad drafts
        choose_renderer(args, scene, settings, None, None, None, background=True)
        print(args.renderer_choice.text(), flush=True)
        for line in auto_lines(args, settings)[1:]:
            print(line, flush=True)
    camera = camera_from_args(args, scene, settings, orbit_up=True)   # the orbit keeps --up
    # refused here, before a window opens (the camera model too), naming the viewer's renderers
    check(args.renderer, scene=scene, settings=settings, model=camera.model, interactive=True)
    if args.renderer == RendererKind.CPU.value:
        from ..renderers.cpu import prepare
        prepare()     # compiled on first use (half a minute), not in the window's first rest
    cameras = load_cameras(args.camera) if args.camera is not None else []
    if args.camera is not None and not (args.width or args.height):
        camera = _fit(camera)

    from ..viewer.app import Viewer, ViewerOptions  # glfw only when a window is wanted

    up, up_source = resolve_up(args.up, args.scene, args.camera)
    print(f"up: {up_source} (U cycles +y / -y / +z / -z)", flush=True)
    options = ViewerOptions(title=f"splatgl view - {Path(path).name}",
                            screenshot_dir=args.screenshot_dir, render_args=_render_args(args),
                            vsync=not args.no_vsync and args.benchmark is None,
                            up=tuple(float(v) for v in up),
                            projection=args.projection if args.projection not in (None, "perspective") else None,
                            fisheye_fov=args.fov if args.projection == "fisheye" else None,
                            stereo=args.stereo,
                            target_fps=target_fps,
                            scene_path=Path(path), stream=stream)
    try:
        return _show(args, scene, settings, camera, cameras, options)
    finally:
        if stream is not None:
            stream.close()


def _open_stream(args: argparse.Namespace, memory: int):
    """``view --memory``: the level of detail streamed under ``memory`` bytes."""
    from ..lod.budget import format_size
    from ..lod.io import is_lod_file
    from ..lod.selection import LodSettings
    from ..lod.stream_view import StreamedScene

    chunked = is_chunked_scene(args)
    if args.scene is None or not (chunked or is_lod_file(args.scene)):
        raise SplatglError(f"{args.scene}: not a level-of-detail file (--memory streams one: a "
                           ".lod.ply, a Streamed SOG lod-meta.json or an LCC meta.lcc); build "
                           "one with 'splatgl lod SCENE -o SCENE.lod.ply'")

    def wake() -> None:   # a chunk arrived (a loader thread): the window's loop draws again
        import glfw
        glfw.post_empty_event()

    if chunked:   # a Streamed SOG or LCC: a level per chunk
        from ..lod.stream_levels_view import ChunkedScene

        stream = ChunkedScene(args.scene, LodSettings(), memory, on_change=wake,
                              level=stream_level(args))
        print(f"streaming {args.scene}: {stream.framing.count:,} splats at level 0 in "
              f"{stream.levels} levels under {format_size(memory)} (--memory)", flush=True)
        return stream
    stream = StreamedScene(args.scene, LodSettings(), memory, on_change=wake)
    print(f"streaming {args.scene}: {stream.framing.count:,} leaves in {stream.lazy.levels} "
          f"levels under {format_size(memory)} (--memory)", flush=True)
    return stream


def _switch(viewer, choice) -> None:
    """The CPU renderer's kernels are ready (the compiling thread): its exact frame from the
    viewer's next step, where the viewer still draws with quad; the loop is woken for it."""
    import glfw

    viewer.switch_to = RendererKind.CPU
    glfw.post_empty_event()


def _show(args, scene, settings, camera, cameras, options) -> int:
    from ..viewer.app import Viewer

    with Viewer(scene, settings, camera, cameras, args.camera_index or 0,
                RendererKind(args.renderer), options) as viewer:
        choice = getattr(args, "renderer_choice", None)
        if choice is not None and choice.kernels_missing:   # compiling: cpu once they are ready
            renderer_auto.when_compiled(lambda: _switch(viewer, choice))
        print(f"OpenGL {viewer.ctx.info['GL_VERSION']} on {viewer.ctx.info['GL_RENDERER']}", flush=True)
        if args.benchmark is not None:
            viewer.step()  # first frame: uploads and compiles
            r = viewer.benchmark(args.benchmark)
            # The per-frame figures only where given: ../shared/peer-race (and other timing
            # wrappers) replace Viewer.benchmark with a copy of its older body, which returns
            # the means alone; a KeyError here ended every such run.
            per_frame = (f"; per frame: median {r['fps_median']:.2f} fps, 10th percentile "
                         f"{r['fps_p10']:.2f}" if "fps_median" in r and "fps_p10" in r else "")
            print(f"benchmark: {args.benchmark} frames at {viewer.size[0]}x{viewer.size[1]}, "
                  f"{viewer.kind.value}: {r['fps']:.2f} fps, frame {r['frame'] * 1e3:.1f} ms "
                  f"(sort {r['sort'] * 1e3:.1f} ms, draw {r['draw'] * 1e3:.1f} ms){per_frame}",
                  flush=True)
            return 0
        viewer.run()
    return 0

