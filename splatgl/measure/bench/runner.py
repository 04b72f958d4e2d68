"""Running the benchmark: camera paths, timed frames, errors against the reference."""

from __future__ import annotations

import dataclasses
import math
import statistics
import time
from dataclasses import asdict, dataclass, field
from typing import Callable

import numpy as np

from ...cameras.camera import Camera
from ...cameras.poses import orbit
from ...cameras.registry import retarget
from ...cameras.view import View
from .probes import GpuTimer, count_fragments
from ..evaluation.metrics import image_errors, psnr
from ...api import Renderer, default_camera, render_reference_rgba
from ...scene.splats import Scene, SplatKind
from ...scene.settings import GpuStorage, RendererKind, RenderSettings
from ...order.sort import depth_sort
from .configs import BenchConfig, RowKind, configurations
from .limit import LimitRenderer
from ...renderers.registry import own_settings

Progress = Callable[[int, int, str], None]


@dataclass(frozen=True)
class BenchOptions:
    """How the benchmark runs.

    Attributes:
        width, height: image size in pixels.
        frames: timed frames per configuration, along an orbit (the camera moves every frame,
            so cull and sort run every frame, and a lazy re-sort shows its lag).
        orbit_step: degrees of azimuth per frame.
        error_frames: which frames are compared with the reference (indices into the path).
        quick: fewer rows (one per question), for CI.
        groups: only these groups of rows (plus default and limit); None = all.
    """

    width: int = 1280
    height: int = 720
    frames: int = 12
    orbit_step: float = 2.0
    error_frames: tuple[int, ...] = (3, 7, 11)
    quick: bool = False
    groups: frozenset[str] | None = None


@dataclass(frozen=True)
class BenchRow:
    """One configuration on one scene; times in milliseconds."""

    scene: str
    splats: int
    config: str
    group: str
    renderer: str
    frame_ms: float
    frame_ms_p10: float
    frame_ms_p90: float
    stages_ms: dict = field(default_factory=dict)
    gpu_draw_ms: float | None = None
    drawn: int | None = None
    fragments_shaded: int | None = None
    fragments_kept: int | None = None
    fragment_efficiency: float | None = None
    psnr: float | None = None
    max_abs: float | None = None
    off_1: float | None = None
    limit_ratio: float | None = None
    #: Early termination: splats its occlusion cull dropped (median over the path), and the
    #: NumPy reference's blended fragments (alpha >= 1/255 before the stop) on the counting view.
    occlusion_culled: int | None = None
    reference_fragments: int | None = None
    #: Quad rows: the scene's GPU storage bytes per splat.  Group ``storage``: the lowest PSNR
    #: over the error frames against the same settings with float32 storage.
    gpu_bytes_per_splat: float | None = None
    psnr_float32: float | None = None
    #: Fragments rasterised on the counting view, rejected by early termination's depth test
    #: included (rows with early termination on only; otherwise the same as fragments_shaded).
    fragments_rasterised: int | None = None
    #: Quad rows: the share of the timed frames drawn in early-termination batches (1 with
    #: ``early-stop=on``, 0 with off, per view with auto).
    batched_share: float | None = None
    #: ``early-stop=auto`` rows: the coverage estimate of the fragments a plain draw would
    #: rasterise (median over the path), which auto's decision rests on.
    fragments_estimate: int | None = None
    #: Quad rows: the most a timed frame moved between host and device, apart from the
    #: one-time scene upload (``upload_bytes``, ``readback_bytes``, ``syncs``; splatgl/gl/
    #: transfers.py): what ``--timings`` reports for a frame.
    transfers: dict | None = None

    def as_dict(self) -> dict:
        d = asdict(self)
        for key in ("psnr", "psnr_float32"):
            if d[key] is not None and math.isinf(d[key]):
                d[key] = None  # JSON has no infinity; None reads as "identical"
        return d


def orbit_path(scene: Scene, options: BenchOptions, start: int = 0) -> list[Camera]:
    """Cameras orbiting the scene's centre at the default framing distance and elevation."""
    base = default_camera(scene, options.width, options.height)
    lo, hi = scene.robust_bounds
    centre = 0.5 * (lo + hi)
    distance = float(np.linalg.norm(base.center - centre))
    return [base.with_pose(orbit(centre, distance, 180.0 + options.orbit_step * (start + i), 20.0))
            for i in range(options.frames)]


def median_seconds(fn, repeats: int):
    """``(median seconds, last result)`` of ``repeats`` calls of ``fn()`` (the benchmarks'
    scripts time single stages this way)."""
    times, result = [], None
    for _ in range(repeats):
        t0 = time.perf_counter()
        result = fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times), result


def sort_benchmark(n: int = 1_000_000, repeats: int = 7, seed: int = 0) -> float:
    """Median milliseconds of the exact 32-bit depth sort of ``n`` keys."""
    rng = np.random.default_rng(seed)
    depth = rng.uniform(0.1, 100.0, n).astype(np.float32)
    idx = np.arange(n, dtype=np.uint32)
    return median_seconds(lambda: depth_sort(depth, idx), repeats)[0] * 1e3


def _stage_ms(times) -> dict[str, float]:
    if times is None:
        return {}
    out = {}
    for name, value in vars(times).items():
        if isinstance(value, float):
            out[name] = value * 1e3
    return out


class _Runner:
    def __init__(self, renderer: Renderer, scene: Scene, config: BenchConfig):
        self.kind = config.kind
        self.settings = config.settings
        if config.kind is RowKind.LIMIT:
            self.impl = LimitRenderer(renderer.ctx, scene, config.settings, renderer.programs)
        elif config.kind in (RowKind.QUAD, RowKind.TILE, RowKind.CPU):
            kind = RendererKind(config.kind.value)   # its own part of the settings (--sort)
            self.impl = renderer.renderer_for(scene, own_settings(config.settings, kind), kind)
        else:
            self.impl = None
        self.scene = scene

    def view(self, camera: Camera) -> View:
        return View.of(camera, self.settings, self.scene)

    def render(self, camera: Camera) -> np.ndarray:
        if self.impl is None:
            return render_reference_rgba(self.scene, camera, self.settings)
        return self.impl.render(self.view(camera)).rgba

    def release(self) -> None:
        if self.kind is RowKind.LIMIT:
            self.impl.release()


def bench_scene(renderer: Renderer, name: str, scene: Scene, options: BenchOptions,
                base: RenderSettings = RenderSettings(), progress: Progress | None = None) -> list[BenchRow]:
    """All rows for one scene.  The reference images of the error frames are computed once."""
    from ...order import kernels as cull_kernel

    cull_kernel.kernel(wait=True)  # where installed, every timed row takes the compiled cull
    cameras = orbit_path(scene, options)
    warm = orbit_path(scene, BenchOptions(options.width, options.height, 1, options.orbit_step), start=-3)[0]
    err_frames = [i for i in options.error_frames if i < len(cameras)] or [len(cameras) - 1]
    configs = configurations(base, scene.sh_degree, options.quick, options.groups,
                             cpu=None if scene.kind is SplatKind.GAUSSIAN_3D else False)
    total = len(err_frames) + len(configs) + any(c.group == "early-stop" for c in configs)
    step = 0

    def tick(what: str) -> None:
        nonlocal step
        step += 1
        if progress is not None:
            progress(step, total, f"{name}: {what}")

    ref_fragments = None
    if any(c.group == "early-stop" for c in configs):
        # The fill floor of a renderer that stops exactly, on the view count_fragments uses.
        from ...reference import render_reference
        ref_fragments = int(render_reference(scene, cameras[0], base, compat=base.convention).n_blended.sum())
        tick("reference fragments")
    refs, ref_ms = {}, []
    for i in err_frames:
        t0 = time.perf_counter()
        refs[i] = render_reference_rgba(scene, cameras[i], base)
        ref_ms.append((time.perf_counter() - t0) * 1e3)
        tick(f"reference frame {i}")

    f32_images: dict[int, np.ndarray] = {}
    if any(c.group == "storage" for c in configs):
        # What the storage rows are measured against: the same settings with float32 storage.
        f32 = _Runner(renderer, scene, dataclasses.replace(
            configs[0], settings=dataclasses.replace(base, gpu_storage=GpuStorage.FLOAT32)))
        f32_images = {i: f32.render(cameras[i]) for i in err_frames}
        f32.release()

    # Warm-up pass over the whole path with the first configuration, untimed: the first
    # frames after loading a scene ran ~20% slow (page faults, llvmpipe's shader JIT),
    # which made the default row (always first) look worse than the same settings later.
    first = _Runner(renderer, scene, configs[0])
    for cam in [warm] + cameras:
        first.render(cam)
    first.release()

    rows: list[BenchRow] = []
    for config in configs:
        if config.kind is RowKind.REFERENCE:
            rows.append(BenchRow(name, scene.count, config.name, config.group, "reference",
                                 statistics.median(ref_ms), min(ref_ms), max(ref_ms), psnr=math.inf,
                                 max_abs=0.0, off_1=0.0))
            tick(config.name)
            continue
        runner = _Runner(renderer, scene, config)
        timer = GpuTimer(runner.impl).attach() if config.kind is RowKind.QUAD else None
        # Projection rows time the same poses and image size through another camera model;
        # their accuracy against the reference is checked in tests/cameras/test_lens.py, not here.
        path = ([retarget(c, config.projection) for c in cameras]
                if config.projection else cameras)
        runner.render(retarget(warm, config.projection) if config.projection else warm)
        runner.render(path[-1])
        times, stages, gpu, drawn, errs, occluded, f32_psnr, batched = [], [], [], [], [], [], [], []
        estimates, moved = [], []
        for i, cam in enumerate(path):
            t0 = time.perf_counter()
            img = runner.render(cam)
            times.append((time.perf_counter() - t0) * 1e3)
            last = getattr(runner.impl, "last_times", None)
            stages.append(_stage_ms(last))
            d = getattr(last, "drawn", None)
            drawn.append(None if d is None or d < 0 else d)   # < 0: counted on the device
            occluded.append(getattr(last, "occlusion_culled", None))
            batched.append(bool(getattr(last, "batched", False)))
            estimates.append(getattr(last, "fragments_estimate", 0))
            moved.append(getattr(last, "transfers", None))
            if timer is not None and timer.last_ns is not None:
                gpu.append(timer.last_ns / 1e6)
            if i in refs and config.kind is not RowKind.LIMIT and not config.projection:
                errs.append(image_errors(img, refs[i]))
            if config.group == "storage" and i in f32_images:
                f32_psnr.append(psnr(img[..., :3], f32_images[i][..., :3]))
        shaded = kept = eff = rasterised = bytes_per_splat = None
        if config.kind is RowKind.QUAD:
            bytes_per_splat = runner.impl.buffers.nbytes / max(scene.count, 1)
            timer.release()
            shaded, kept = count_fragments(runner.impl, runner.view(path[0]))
            eff = kept / shaded if shaded else None
            if runner.impl.batches.batched:  # the counting view ran early termination
                rasterised = count_fragments(runner.impl, runner.view(path[0]), rasterised=True)[0]
        runner.release()
        keys = stages[0].keys() if stages else []
        rows.append(BenchRow(
            name, scene.count, config.name, config.group, config.kind.value,
            statistics.median(times), float(np.percentile(times, 10)), float(np.percentile(times, 90)),
            {k: statistics.median(s[k] for s in stages) for k in keys},
            statistics.median(gpu) if gpu else None,
            int(statistics.median(d for d in drawn if d is not None)) if any(d is not None for d in drawn) else None,
            shaded, kept, eff,
            min(e.psnr for e in errs) if errs else None,
            max(e.max_abs for e in errs) if errs else None,
            max(e.off_1 for e in errs) if errs else None,
            occlusion_culled=(int(statistics.median(occluded)) if config.kind is RowKind.QUAD
                              and None not in occluded and occluded else None),
            reference_fragments=ref_fragments if config.kind is RowKind.QUAD else None,
            gpu_bytes_per_splat=bytes_per_splat,
            psnr_float32=min(f32_psnr) if f32_psnr else None,
            fragments_rasterised=rasterised,
            batched_share=(sum(batched) / len(batched)
                           if config.kind is RowKind.QUAD and batched else None),
            fragments_estimate=(int(statistics.median(estimates))
                                if config.kind is RowKind.QUAD and any(estimates) else None),
            transfers=({k: max(m.as_dict()[k] for m in moved) for k in moved[0].as_dict()}
                       if moved and None not in moved else None),
        ))
        tick(config.name)
    limit = next((r.frame_ms for r in rows if r.group == "limit"), None)
    if limit:
        rows = [BenchRow(**{**asdict(r), "limit_ratio": r.frame_ms / limit}) for r in rows]
    return rows
