"""A moving-camera frame's order stage, CPU order against device order (issue 40's llvmpipe
target: "the GPU sort of a 1M-splat frame at most 1.5x the CPU sort in the same run").

``benchmarks/radix_sort.py`` times the radix sort alone against NumPy's sort of the same keys.
This one times what the quad path pays per moving-camera frame to produce its draw order, on
the scale benchmark's scene (:func:`splatgl.measure.bench.scale.scene_file`, built on first use)
along an orbit, for each camera model of ``--views``:

- ``exact`` (``--sort exact``, the CPU order): :meth:`QuadRenderer.order` (the view's cull with
  its depth keys, NumPy's sort), then the upload of the order to the GPU as the renderer does it
  (``QuadResources.upload``), to ``glFinish``;
- ``gpu`` (``--sort gpu``, the device-resident order, :mod:`splatgl.renderers.quad_device`):
  ``DeviceOrder.run`` (order_cull, order_scan, order_compact, the radix sort, all on the
  device), to ``glFinish`` so the device's work is counted.

For context it also times the whole frame both ways (``QuadRenderer.render``: order, upload,
pre-pass, draw, image read back; the ``--timings`` stages, where the device order's cull and sort
are only the time to issue them and its device work lands in the pre-pass and draw), and keeps
the transfer counters (:mod:`splatgl.gl.transfers`) of the order stage and of the frame: the
most over the timed frames.

A round runs, on fresh views (2 degrees of orbit a view), the order stage of one order then of
the other, then a frame of each (which of the two goes first alternates round by round), so
load that changes during the run shifts both alike; the first round is an untimed warm-up (it
builds the cull data, compiles the shaders, grows the buffers) whose frames are compared
(``identical_image``).  Figures are medians of ``--frames`` rounds; ``gpu/exact`` is the ratio of
the medians.  The CPU cull is the compiled one where numba is installed (what the renderer runs
from its second view on; ``--numpy-cull``: NumPy's).  Prints the machine line (CPU, SIMD level,
cores, GL renderer) and the load average before and after; ``--json FILE`` also writes them
(atomically) with the rows.

Times depend on the machine and on what else runs on it: run it on a quiet machine::

    python benchmarks/frame_order.py --frames 7 --json docs/results/frame-order-MACHINE-DATE.json
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import time

import numpy as np
from _script import run

VIEWS = ("pinhole", "fisheye", "equirect", "orthographic")
STAGES = ("cull", "sort", "upload", "prepass", "draw", "readback")
TRANSFER_FIELDS = ("upload_bytes", "readback_bytes", "syncs")


def check_views(text: str) -> tuple[str, ...]:
    """'pinhole,fisheye' -> ('pinhole', 'fisheye'); unknown names refused in one line."""
    from splatgl.errors import SplatglError

    views = tuple(v.strip() for v in text.split(",") if v.strip())
    bad = [v for v in views if v not in VIEWS]
    if bad or not views:
        raise SplatglError(f"--views: {', '.join(bad) or repr(text)} is not a view "
                           f"(expected some of {', '.join(VIEWS)})")
    return views


def cameras(scene, view: str, count: int, width: int, height: int) -> list:
    """``count`` cameras of ``view``'s model along an orbit that frames the scene, 2 degrees a
    step (the scale benchmark's orbit; the orthographic camera zoomed to frame the scene)."""
    from splatgl.cameras.framing import default_camera
    from splatgl.cameras.poses import orbit
    from splatgl.cameras.registry import retarget

    base = default_camera(scene, width, height)
    lo, hi = scene.robust_bounds
    centre = 0.5 * (lo + hi)
    dist = float(np.linalg.norm(base.center - centre))
    if view == "orthographic":
        base = default_camera(scene, width, height, projection="orthographic")
    cams = [base.with_pose(orbit(centre, dist, 2.0 * i, 20.0)) for i in range(count)]
    if view == "fisheye":
        return [retarget(c, "fisheye", 180.0) for c in cams]
    if view == "equirect":
        return [retarget(c, "equirectangular") for c in cams]
    return cams


def exact_order(quad, view) -> dict:
    """The CPU order stage of ``view``: cull and keys, sort, upload of the order, to a finish."""
    from splatgl.gl.transfers import transfers

    counter = transfers(quad.ctx)
    before = counter.snapshot()
    t0 = time.perf_counter()
    order = quad.order(view)
    t1 = time.perf_counter()
    quad.gpu.upload(order, quad.rows.slot_weights)
    quad.ctx.finish()
    counter.sync()
    t2 = time.perf_counter()
    times = quad.rows.times
    return {"ms": 1e3 * (t2 - t0), "cull_ms": 1e3 * times.cull, "sort_ms": 1e3 * times.sort,
            "upload_ms": 1e3 * (t2 - t1), "kept": int(order.size),
            "transfers": counter.snapshot().since(before).as_dict()}


def gpu_order(quad, view) -> dict:
    """The device order stage of ``view``: cull, scan, compact and sort issued, to a finish."""
    from splatgl.errors import SplatglError
    from splatgl.gl.transfers import transfers

    device = quad.device_order(view)
    if device is None:
        raise SplatglError(f"the device order does not cover the {view.model.name} view")
    counter = transfers(quad.ctx)
    before = counter.snapshot()
    t0 = time.perf_counter()
    cull, sort = device.run(view, 3 if quad.gpu.triangles else 4, quad.options.antialias)
    quad.ctx.finish()
    counter.sync()
    t1 = time.perf_counter()
    return {"ms": 1e3 * (t1 - t0), "issue_ms": 1e3 * (cull + sort),
            "transfers": counter.snapshot().since(before).as_dict()}


def frame(quad, view) -> tuple[dict, np.ndarray]:
    """One whole frame (order, upload, pre-pass, draw, read back): its time, the ``--timings``
    stages and transfers; and the image."""
    t0 = time.perf_counter()
    rgba = quad.render(view).rgba
    t1 = time.perf_counter()
    t = quad.last_times
    return ({"ms": 1e3 * (t1 - t0), "stages": {k: 1e3 * getattr(t, k) for k in STAGES},
             "transfers": t.transfers.as_dict(), "batched": bool(t.batched),
             "device_order": bool(t.device_order)}, rgba)


def _median(values) -> float:
    return float(statistics.median(values))


def _most(runs: list[dict]) -> dict:
    """The most of each transfer counter over ``runs``."""
    return {k: max(r["transfers"][k] for r in runs) for k in TRANSFER_FIELDS}


def measure_view(scene, quads: dict, view_name: str, frames: int, width: int, height: int) -> dict:
    """One row: ``view_name``'s order stage and frame both ways (see the module doc)."""
    from splatgl.cameras.view import View

    cams = cameras(scene, view_name, 2 * (frames + 1), width, height)
    views = {key: [View.of(c, quad.options, scene) for c in cams] for key, quad in quads.items()}
    orders = {"exact": [], "gpu": []}
    frames_run = {"exact": [], "gpu": []}
    images = {}
    for r in range(frames + 1):
        keys = ("exact", "gpu") if r % 2 == 0 else ("gpu", "exact")
        for key in keys:   # the order stage of view 2r
            fn = exact_order if key == "exact" else gpu_order
            orders[key].append(fn(quads[key], views[key][2 * r]))
        for key in keys:   # a whole frame of view 2r + 1
            result, images[key] = frame(quads[key], views[key][2 * r + 1])
            frames_run[key].append(result)
        if r == 0:   # the warm-up round: the frames compared, the device's count read back
            identical = bool(np.array_equal(images["exact"], images["gpu"]))
            kept_gpu = quads["gpu"].device_order(views["gpu"][1]).kept()
            kept_exact = quads["exact"].last_times.drawn
    ex, gp = orders["exact"][1:], orders["gpu"][1:]
    fx, fg = frames_run["exact"][1:], frames_run["gpu"][1:]
    exact_ms, gpu_ms = _median([o["ms"] for o in ex]), _median([o["ms"] for o in gp])
    exact_frame, gpu_frame = _median([f["ms"] for f in fx]), _median([f["ms"] for f in fg])
    return {
        "splats": scene.count, "view": view_name, "kept": kept_exact, "kept_gpu": kept_gpu,
        "identical_image": identical,
        "exact_order_ms": exact_ms, "gpu_order_ms": gpu_ms, "order_gpu_over_exact": gpu_ms / exact_ms,
        "exact_order_stages_ms": {k: _median([o[f"{k}_ms"] for o in ex])
                                  for k in ("cull", "sort", "upload")},
        "gpu_order_issue_ms": _median([o["issue_ms"] for o in gp]),
        "exact_frame_ms": exact_frame, "gpu_frame_ms": gpu_frame,
        "frame_gpu_over_exact": gpu_frame / exact_frame,
        "exact_frame_stages_ms": {k: _median([f["stages"][k] for f in fx]) for k in STAGES},
        "gpu_frame_stages_ms": {k: _median([f["stages"][k] for f in fg]) for k in STAGES},
        "gpu_frame_device_order": all(f["device_order"] for f in fg),
        "batched": {"exact": fx[-1]["batched"], "gpu": fg[-1]["batched"]},
        "transfers": {"exact_order": _most(ex), "gpu_order": _most(gp),
                      "exact_frame": _most(fx), "gpu_frame": _most(fg)},
    }


def measure(renderer, n: int, frames: int, width: int, height: int, views: tuple[str, ...],
            cache=None) -> list[dict]:
    """The rows of the ``n``-splat scene, one per view, both renderers on ``renderer``'s context."""
    from splatgl.formats import load_scene
    from splatgl.measure.bench.scale import scene_file
    from splatgl.renderers.quad import QuadRenderer
    from splatgl.scene.settings import RenderSettings, SortKey

    scene = load_scene(scene_file(n, 0, cache), progress=lambda *a: None)
    quads = {}
    try:
        for key, sort in (("exact", SortKey.EXACT), ("gpu", SortKey.GPU)):
            quads[key] = QuadRenderer(renderer.ctx, scene, RenderSettings(sort_key=sort),
                                      renderer.programs)
        return [measure_view(scene, quads, v, frames, width, height) for v in views]
    finally:
        for quad in quads.values():
            quad.release()


def report(renderer, sizes, frames: int, width: int, height: int, views: tuple[str, ...],
           numpy_cull: bool = False, cache=None, start=lambda machine, load: None,
           log=lambda row: None) -> dict:
    """The JSON document: machine, load average at the start and the end, the rows
    (``start(machine, load average)`` before the first, ``log(row)`` after each)."""
    from splatgl.errors import SplatglError
    from splatgl.gl.context import renderer_name
    from splatgl.measure.bench.machine import machine_info
    import splatgl.order.chunks  # noqa: F401 (registers the compiled cull with the loader)
    from splatgl.order import kernels as cull_kernel

    if frames < 1:
        raise SplatglError(f"--frames must be at least 1, got {frames}")
    machine = machine_info(renderer_name(renderer.ctx))
    compiled = not numpy_cull and cull_kernel.kernel(wait=True) is not None   # loaded first
    machine["cull"] = "compiled (numba)" if compiled else "numpy"
    load_start = os.getloadavg()
    start(machine, load_start)
    rows = []
    cull_kernel.set_policy("wait" if compiled else "off")
    try:
        for n in sizes:
            for row in measure(renderer, n, frames, width, height, views, cache):
                rows.append(row)
                log(row)
    finally:
        cull_kernel.set_policy("auto")
    return {"machine": machine, "frames": frames, "width": width, "height": height,
            "interleaved": True, "load_average": {"start": list(load_start),
                                                  "end": list(os.getloadavg())},
            "rows": rows}


def line(r: dict) -> str:
    s = r["exact_order_stages_ms"]
    t = r["transfers"]["gpu_frame"]
    return (f"{r['splats']:>9,} {r['view']:>12} {r['kept']:>9,} {r['exact_order_ms']:>8.1f} "
            f"{s['cull']:>6.1f} {s['sort']:>6.1f} {s['upload']:>6.1f} {r['gpu_order_ms']:>8.1f} "
            f"{r['order_gpu_over_exact']:>9.2f} {r['exact_frame_ms']:>8.1f} "
            f"{r['gpu_frame_ms']:>8.1f} {r['frame_gpu_over_exact']:>9.2f} "
            f"{t['upload_bytes']:>7,} {t['readback_bytes']:>10,} "
            f"{'yes' if r['identical_image'] else 'NO':>4}")


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                epilog=__doc__[__doc__.index("Times depend"):],
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--sizes", default="1M", help="scene sizes (splats), 'k'/'M' suffixes")
    p.add_argument("--frames", type=int, default=5, help="timed rounds per view (medians)")
    p.add_argument("--width", type=int, default=1280)
    p.add_argument("--height", type=int, default=720)
    p.add_argument("--views", default=",".join(VIEWS),
                   help=f"camera models, comma-separated (default {','.join(VIEWS)})")
    p.add_argument("--numpy-cull", action="store_true",
                   help="the CPU order with NumPy's cull (default: the compiled one if installed)")
    p.add_argument("--cache", default=None, help="folder of the built scenes (default: the "
                   "scale benchmark's, in the temp folder)")
    p.add_argument("--json", default=None, metavar="FILE", help="also write the figures here")
    args = p.parse_args()
    from splatgl.api import Renderer
    from splatgl.errors import SplatglError
    from splatgl.measure.bench.machine import describe
    from splatgl.measure.bench.scale import parse_sizes
    from splatgl.writing.atomic import atomic_write_text

    sizes = parse_sizes(args.sizes, (1_000_000,), "--sizes")
    views = check_views(args.views)
    if args.json and not os.path.isdir(os.path.dirname(os.path.abspath(args.json))):
        raise SplatglError(f"--json: the folder of {args.json} does not exist")

    def start(machine, load):
        print(describe(machine), flush=True)
        print(f"# load average {load[0]:.2f} (1 min), {load[1]:.2f} (5 min) at the start; "
              f"{args.width}x{args.height}; medians of {args.frames} interleaved rounds; ms; "
              "order = the order stage to a finish (exact: cull, sort, upload; gpu: on the "
              "device); frame = order to image read back; the gpu frame's transfers in bytes",
              flush=True)
        print(f"{'splats':>9} {'view':>12} {'kept':>9} {'exact':>8} {'cull':>6} {'sort':>6} "
              f"{'upload':>6} {'gpu':>8} {'gpu/exact':>9} {'frame ex':>8} {'frame gp':>8} "
              f"{'gpu/exact':>9} {'up':>7} {'read back':>10} same", flush=True)

    with Renderer() as renderer:
        doc = report(renderer, sizes, args.frames, args.width, args.height, views,
                     args.numpy_cull, args.cache, start, lambda r: print(line(r), flush=True))
    end = doc["load_average"]["end"]
    print(f"# load average {end[0]:.2f} (1 min) at the end; cull {doc['machine']['cull']}",
          flush=True)
    if args.json:
        atomic_write_text(args.json, json.dumps(doc, indent=1))


if __name__ == "__main__":
    run(main)
