"""The renderer figures of issue 40 for ``benchmarks/gpu_check.sh --quick``, each saved as made.

Two commands:

- ``scene N [N ...] --cache DIR``: build the N-splat scenes from the shared real files (the
  scale benchmark's builder, :func:`splatgl.measure.bench.scale.scene_file`; cached as INRIA PLY) and
  print their paths, one a line.
- ``renderers FILE [FILE ...] --out FIGURES.jsonl``: for each scene file, each resolution, each
  renderer (quad, tile) and each order (``--sort exact``, ``--sort gpu``): one warm-up frame
  then ``--frames`` frames along an orbit (2 degrees a frame), through
  :class:`splatgl.api.Renderer`.  One JSON line per figure, appended and flushed as soon as it
  is made (a timeout keeps what was done): the median, 10th and 90th percentile frame time
  (wall clock around ``Renderer.render``, the image read back), the median of each stage of
  the renderer's ``last_times`` (what ``render --timings`` prints) and its counts and
  transfers as the last frame left them.  A figure that fails (an order a renderer does not
  have yet) is a line with its ``error``; ``--deadline`` (seconds since the epoch) skips what
  would start after it.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import statistics
import time
from pathlib import Path

from _script import run

RENDERERS = ("quad", "tile")
SORTS = ("exact", "gpu")
#: A figure is not started with less than this many seconds before the deadline.
MIN_SECONDS = 5.0


def _sizes(text: str) -> list[tuple[int, int]]:
    from splatgl.errors import SplatglError

    out = []
    for word in text.split(","):
        try:
            w, h = (int(v) for v in word.lower().split("x"))
        except ValueError:
            raise SplatglError(f"--resolutions: '{word}' is not WIDTHxHEIGHT") from None
        out.append((w, h))
    return out


def _plain(value):
    """A ``last_times`` field as JSON: numbers as they are, anything else by its fields or text."""
    if isinstance(value, (bool, int, float, str)) or value is None:
        return value
    if dataclasses.is_dataclass(value):
        return {k: _plain(v) for k, v in vars(value).items()}
    return str(value)


def _stages(times: list) -> tuple[dict, dict]:
    """(median ms of each float field, the last frame's other fields) of ``last_times``."""
    if not times or times[-1] is None:
        return {}, {}
    stages, rest = {}, {}
    for name, value in vars(times[-1]).items():
        if isinstance(value, float):
            stages[name] = 1e3 * statistics.median(float(getattr(t, name)) for t in times)
        else:
            rest[name] = _plain(value)
    return stages, rest


def _figure(api, scene, path: Path, size, kind, sort: str, frames: int, deadline: float) -> dict:
    import numpy as np

    from splatgl.cameras.framing import default_camera
    from splatgl.cameras.poses import orbit
    from splatgl.scene.settings import RenderSettings

    width, height = size
    row = {"figure": "render", "scene": path.name, "splats": scene.count, "width": width,
           "height": height, "renderer": kind.value, "sort": sort}
    settings = RenderSettings(sort_key=sort)
    base = default_camera(scene, width, height)
    centre = 0.5 * (scene.robust_bounds[0] + scene.robust_bounds[1])
    dist = float(np.linalg.norm(base.center - centre))
    seconds, times = [], []
    for i in range(frames + 1):
        if i and time.time() > deadline:
            row["stopped"] = "deadline"
            break
        cam = base.with_pose(orbit(centre, dist, 2.0 * i, 20.0))
        t0 = time.perf_counter()
        api.render(scene, cam, settings, kind)
        if i:   # the first frame compiles programs and builds the cull data
            seconds.append(time.perf_counter() - t0)
            times.append(api.renderer_for(scene, settings, kind).last_times)
    if seconds:
        ms = sorted(1e3 * s for s in seconds)
        row.update(frames=len(ms), frame_ms=statistics.median(ms), frame_ms_p10=ms[len(ms) // 10],
                   frame_ms_p90=ms[min(len(ms) - 1, (9 * len(ms)) // 10)])
        row["stages_ms"], row["last_frame"] = _stages(times)
    return row


def renderers_main(args: argparse.Namespace) -> None:
    from splatgl.api import Renderer, gl_renderer_name
    from splatgl.formats import load_scene
    from splatgl.scene.settings import RendererKind

    out = Path(args.out)
    deadline = args.deadline or float("inf")
    with out.open("a") as fh:
        def save(row: dict) -> None:
            fh.write(json.dumps(row, default=str) + "\n")
            fh.flush()
            print(json.dumps(row), flush=True)

        for name in args.scenes:
            path = Path(name)
            if time.time() + MIN_SECONDS > deadline:
                save({"figure": "render", "scene": path.name, "skipped": "deadline"})
                continue
            with Renderer() as api:   # a context per scene: the last scene's buffers go with it
                t0 = time.perf_counter()
                scene = load_scene(path, progress=lambda *a: None)
                save({"figure": "load", "scene": path.name, "splats": scene.count,
                      "seconds": time.perf_counter() - t0,
                      "gl_renderer": gl_renderer_name(RendererKind.QUAD, api.ctx)})
                for size in _sizes(args.resolutions):
                    for kind in RENDERERS:
                        for sort in SORTS:
                            save(_guarded(api, scene, path, size, kind, sort, args.frames, deadline))


def _guarded(api, scene, path: Path, size, kind: str, sort: str, frames: int, deadline: float) -> dict:
    """:func:`_figure`, or a row saying why not (the deadline, an error)."""
    from splatgl.scene.settings import RendererKind

    row = {"figure": "render", "scene": path.name, "width": size[0], "height": size[1],
           "renderer": kind, "sort": sort}
    if time.time() + MIN_SECONDS > deadline:
        return {**row, "skipped": "deadline"}
    try:
        return _figure(api, scene, path, size, RendererKind(kind), sort, frames, deadline)
    except Exception as exc:     # noqa: BLE001 - one figure, not the run
        return {**row, "error": f"{type(exc).__name__}: {exc}"}


def scene_main(args: argparse.Namespace) -> None:
    from splatgl.measure.bench.scale import parse_sizes, scene_file

    for n in parse_sizes(args.sizes, (), "sizes"):
        print(scene_file(n, 0, Path(args.cache)), flush=True)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    sub = p.add_subparsers(dest="command", required=True)
    s = sub.add_parser("scene", help="build scenes from the shared real files; print their paths")
    s.add_argument("sizes", help="sizes, e.g. 1M,6M")
    s.add_argument("--cache", required=True, help="folder of the built PLY files")
    r = sub.add_parser("renderers", help="both renderers with both orders, a JSON line a figure")
    r.add_argument("scenes", nargs="+")
    r.add_argument("--resolutions", default="1280x720,1920x1080")
    r.add_argument("--frames", type=int, default=5, help="timed frames a figure (median)")
    r.add_argument("--out", required=True, help="JSON lines appended here, one a figure")
    r.add_argument("--deadline", type=float, default=None, help="seconds since the epoch")
    args = p.parse_args()
    (scene_main if args.command == "scene" else renderers_main)(args)


if __name__ == "__main__":
    run(main)
