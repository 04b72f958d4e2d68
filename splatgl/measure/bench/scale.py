"""Scale benchmark (``splatgl bench --scale``): how load, memory and frame cost grow with the
scene, from 0.1M to 6M splats built from the shared real files.

Each scene is made once by :func:`splatgl.measure.bench.real_scenes.build_real_scene` and written as an
INRIA PLY into a cache folder; each (size, SH degree) is then measured in a fresh child process
(``python -m splatgl.measure.bench.scale FILE ...``) so its peak resident memory is that scene's alone.
The child loads the file (load time, peak RSS over the loading), uploads it (GPU bytes per
splat), renders a few frames of an orbit per resolution through the quad path (cull, sort,
pre-pass, draw, frame) and the tile renderer, and sorts the visible depth keys on the device
(:mod:`splatgl.gl.radix_sort`), checking that order against the CPU sort.

On llvmpipe "GPU" buffers live in the process, so the render peak includes them.
"""

from __future__ import annotations

import json
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

#: Default scene sizes (splats) and the sizes also measured at SH degree 3.
SIZES = (100_000, 300_000, 1_000_000, 3_000_000, 6_000_000)
SH3_SIZES = (1_000_000,)
RESOLUTIONS = ((1280, 720), (1920, 1080))
#: Seed of every built scene (the scenes are a pure function of size, seed and degree).
SEED = 0


def parse_sizes(text: str | None, default: tuple[int, ...], flag: str) -> tuple[int, ...]:
    """'0.1M,300k,6M' -> (100000, 300000, 6000000); None -> ``default``; 'none' -> ().
    Errors name ``flag``, the option the text came from."""
    from ...errors import SplatglError

    if text is None:
        return default
    if text.strip().lower() == "none":
        return ()
    out = []
    for word in text.split(","):
        w = word.strip()
        mult = {"k": 1_000, "m": 1_000_000}.get(w[-1:].lower(), 1)
        try:
            value = float(w[:-1] if mult > 1 else w) * mult
        except ValueError:
            raise SplatglError(f"{flag}: '{w}' is not a size (e.g. 0.1M, 300k, 6M)") from None
        if value < 1:
            raise SplatglError(f"{flag}: sizes must be at least 1 splat, got '{w}'")
        out.append(int(round(value)))
    return tuple(out)


@dataclass(frozen=True)
class ScaleOptions:
    """What the scale benchmark measures.

    Attributes:
        sizes: scene sizes (splats) at SH degree 0.  sh3_sizes: sizes also built at SH degree 3.
        resolutions: (width, height) of the frames.  frames: timed frames per resolution (after
            one untimed warm-up frame), along an orbit of 2 degrees per frame.
        tile_max: time the tile renderer on scenes up to this many splats (0: never; on
            llvmpipe it takes seconds a frame from 0.1M up).
        gpu_sort: also time the device radix sort.
        gpu_storage: the storage of the measured quad and tile renders (:class:`GpuStorage`
            value).  compact: also render the last frame per resolution with compact storage
            (after the memory figures) for its bytes per splat and PSNR against the measured one.
        cache: folder of the built PLY files (default: a splatgl-scale folder in the temp dir).
    """

    sizes: tuple[int, ...] = SIZES
    sh3_sizes: tuple[int, ...] = SH3_SIZES
    resolutions: tuple[tuple[int, int], ...] = RESOLUTIONS
    frames: int = 3
    tile_max: int = 1_000_000
    gpu_sort: bool = True
    gpu_storage: str = "float32"
    compact: bool = True
    cache: Path | None = None


@dataclass(frozen=True)
class ScaleRow:
    """One scene size at one resolution; times in milliseconds, memory in MB (10^6 bytes).

    ``load_s``, ``rss_load_mb`` (peak RSS over the load, above the process's RSS before it),
    ``decoded_mb`` (the scene's arrays) and ``gpu_bytes_per_splat`` are per scene and repeat on
    each resolution's row; ``rss_peak_mb`` is the peak after all frames so far.
    """

    splats: int
    sh_degree: int
    width: int
    height: int
    load_s: float
    file_mb: float
    decoded_mb: float
    rss_load_mb: float
    rss_peak_mb: float
    gpu_bytes_per_splat: float
    visible: int
    stages_ms: dict = field(default_factory=dict)
    quad_frame_ms: float = 0.0
    tile_frame_ms: float | None = None
    sort_gpu_ms: float | None = None
    gpu_sort_identical: bool | None = None
    compact_bytes_per_splat: float | None = None
    compact_psnr: float | None = None
    cull_compiled: bool = False  # the cull ran the compiled kernel (numba installed)


def scene_file(n: int, sh_degree: int, cache: Path | None = None) -> Path:
    """The PLY of the ``n``-splat real-data scene at ``sh_degree``, built and written (atomically)
    on first use, then reused."""
    folder = Path(cache) if cache is not None else Path(tempfile.gettempdir()) / "splatgl-scale"
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / f"real-{n}-sh{sh_degree}-seed{SEED}.ply"
    if not path.is_file():
        from ...formats import save_scene
        from .real_scenes import build_real_scene
        save_scene(path, build_real_scene(n, SEED, sh_degree))
    return path


def rss_mb() -> float:
    """Current resident set size (MB) from /proc/self/statm."""
    with open("/proc/self/statm") as fh:
        pages = int(fh.read().split()[1])
    return pages * os.sysconf("SC_PAGE_SIZE") / 1e6


def peak_rss_mb() -> float:
    """Peak resident set size (MB) of this process image: /proc/self/status VmHWM.  Not
    getrusage's ru_maxrss, which Linux carries across exec from the forked parent (a parent
    that had just built a 6M SH3 scene made the child's figure 3x too high)."""
    try:
        for line in open("/proc/self/status"):
            if line.startswith("VmHWM:"):
                return int(line.split()[1]) / 1e3
    except OSError:
        pass
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1e3  # kB on Linux


def _median(values):
    return float(statistics.median(values)) if values else None


def measure_file(path: Path, options: ScaleOptions) -> list[ScaleRow]:
    """Load ``path`` and measure it (run this in a fresh process: peak RSS is per process)."""
    import numpy as np

    from ...cameras.poses import orbit
    from ...order.cull import CullData, cull_visible
    from ...formats import load_scene
    from ...gl.radix_sort import RadixSorter, device_depth_sort
    from ...cameras.view import View
    from ...renderers.quad import QuadRenderer
    from ...api import Renderer, default_camera
    from ...scene.settings import RenderSettings
    from ...order.sort import depth_sort
    from ...renderers.tile import TileRenderer

    from ...formats import _modules

    renderer = Renderer()  # the context first: its driver memory is not the scene's
    _modules()  # and every format module imported: their code is not the scene either
    from ...order import kernels as cull_kernel
    # the compiled cull (where numba is installed) loaded before anything is measured: its
    # import is not the scene's memory, and every timed frame takes the same cull path
    compiled = cull_kernel.kernel(wait=True) is not None
    base = rss_mb()
    t0 = time.perf_counter()
    scene = load_scene(path, progress=lambda *a: None)
    load_s = time.perf_counter() - t0
    rss_load = peak_rss_mb() - base
    arrays = (scene.means, scene.quats, scene.log_scales, scene.opacity_logits, scene.sh)
    decoded = sum(a.nbytes for a in arrays) / 1e6
    settings = RenderSettings(gpu_storage=options.gpu_storage)
    quad = QuadRenderer(renderer.ctx, scene, settings, renderer.programs)
    rows, last_views = [], []
    for width, height in options.resolutions:
        base_cam = default_camera(scene, width, height)
        centre = 0.5 * (scene.robust_bounds[0] + scene.robust_bounds[1])
        dist = float(np.linalg.norm(base_cam.center - centre))
        cams = [base_cam.with_pose(orbit(centre, dist, 2.0 * i, 20.0)) for i in range(options.frames + 1)]
        times = []
        for cam in cams:
            image = quad.render(View.of(cam, settings, scene)).rgba
            times.append(quad.last_times)
        last_views.append((cams[-1], image))
        times = times[1:]  # the first frame compiles programs and builds the cull data
        stages = {k: 1e3 * _median([getattr(t, k) for t in times])
                  for k in ("cull", "sort", "upload", "prepass", "draw", "readback")}
        frame = 1e3 * _median([t.total for t in times])
        visible = int(times[-1].drawn)
        tile_ms = None
        if scene.count <= options.tile_max:
            tile = TileRenderer(renderer.ctx, scene, settings, renderer.programs)
            tt = []
            for cam in cams:
                t1 = time.perf_counter()
                tile.render(View.of(cam, settings, scene))
                tt.append(time.perf_counter() - t1)
            tile.release()
            tile_ms = 1e3 * _median(tt[1:])
        rss_peak = peak_rss_mb() - base
        sort_gpu = identical = None
        if options.gpu_sort:  # after the memory figure: its own cull data is a second copy
            view = View.of(cams[-1], settings, scene)
            keep, depth = cull_visible(CullData.from_scene(scene), view.anchored, view.near)
            sorter = RadixSorter(renderer.ctx, renderer.programs)
            runs = []
            for _ in range(3):
                t1 = time.perf_counter()
                order = device_depth_sort(sorter, depth, keep)
                runs.append(time.perf_counter() - t1)
            sort_gpu = 1e3 * _median(runs[1:])
            identical = bool(np.array_equal(order, depth_sort(depth, keep)))
            sorter.release()
            del keep, depth, order
        rows.append(ScaleRow(scene.count, scene.sh_degree, width, height, load_s,
                             path.stat().st_size / 1e6, decoded, rss_load, rss_peak,
                             quad.buffers.nbytes / scene.count, visible, stages, frame, tile_ms,
                             sort_gpu, identical, cull_compiled=compiled))
    quad.release()
    if options.compact:
        rows = _with_compact(renderer, scene, last_views, rows)
    renderer.close()
    return rows


def _with_compact(renderer, scene, views, rows: list[ScaleRow]) -> list[ScaleRow]:
    """``rows`` with the compact storage's bytes per splat and its PSNR against each row's
    last frame (``views``: (camera, image) per row), rendered by a second quad renderer."""
    from dataclasses import replace

    from ...cameras.view import View
    from ..evaluation.metrics import psnr
    from ...renderers.quad import QuadRenderer
    from ...scene.settings import GpuStorage, RenderSettings

    settings = RenderSettings(gpu_storage=GpuStorage.COMPACT)
    quad = QuadRenderer(renderer.ctx, scene, settings, renderer.programs)
    out = []
    for row, (cam, image) in zip(rows, views):
        value = psnr(quad.render(View.of(cam, settings, scene)).rgba[..., :3], image[..., :3])
        out.append(replace(row, compact_bytes_per_splat=quad.buffers.nbytes / scene.count,
                           compact_psnr=None if value == float("inf") else value))
    quad.release()
    return out


def run_scale(options: ScaleOptions, log=print) -> list[ScaleRow]:
    """Build (or reuse) each scene, measure each in a child process; rows in size order."""
    jobs = [(n, 0) for n in options.sizes] + [(n, 3) for n in options.sh3_sizes]
    rows: list[ScaleRow] = []
    for n, degree in sorted(jobs):
        t0 = time.perf_counter()
        path = scene_file(n, degree, options.cache)
        log(f"scale: {n:,} splats SH{degree}: scene file ready ({time.perf_counter() - t0:.1f} s), "
            "measuring")
        payload = json.dumps({**asdict(options), "cache": None})
        proc = subprocess.run([sys.executable, "-m", "splatgl.measure.bench.scale", str(path), payload],
                              capture_output=True, text=True)
        if proc.returncode != 0:
            tail = (proc.stderr.strip().splitlines() or ["no output"])[-1]
            log(f"scale: {n:,} splats SH{degree} failed: {tail}")
            continue
        rows += [ScaleRow(**r) for r in json.loads(proc.stdout)]
    return rows


def _options_from_json(text: str) -> ScaleOptions:
    d = json.loads(text)
    d["sizes"], d["sh3_sizes"] = tuple(d["sizes"]), tuple(d["sh3_sizes"])
    d["resolutions"] = tuple(tuple(r) for r in d["resolutions"])
    return ScaleOptions(**d)


if __name__ == "__main__":  # the child process of run_scale
    result = measure_file(Path(sys.argv[1]), _options_from_json(sys.argv[2]))
    print(json.dumps([asdict(r) for r in result]))
