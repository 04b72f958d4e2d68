"""The interactive benchmark: a scripted 10 s camera flight through the viewer's session.

``splatgl bench --interactive`` flies a camera over each scene in real time, through the same
:class:`~splatgl.interactive.session.Session` the viewer uses (headless: no window, so no
present or swap), and measures what a person at the window would see:

- frames a second while moving (median and 10th percentile of the frame rate), with the level
  each frame was drawn at;
- the PSNR of each moving frame against the exact render of the same camera (the frame is
  drawn again at its level after the flight, so measuring does not slow the flight);
- the time from rest to the exact frame;
- input latency: input arriving at random moments of a refinement (the exact frame drawing at
  rest), timed until the frame for the new camera is done.

Over a level of detail streamed from disk (``stream``: ``bench --scale --lod``'s flight step) the
session is the viewer's over the resident chunks
(:func:`splatgl.interactive.stream_levels.streamed_session`, as ``splatgl view --memory``): moving
frames draw the budget's level of what is resident, and the rest ends when the exact frame is
drawn with every chunk it needs in (or gathered, where they do not fit the cache at once).
Each frame then records the resident memory, the chunks loaded and the process's resident set
(:attr:`FlightResult.samples`); moving frames are not scored and no latency is measured (their exact frames would wait for chunks).

The flight (:func:`flight_camera`): an orbit at the default framing distance (0-5 s), a fly-in
from twice that distance to a third of it (5-8 s), then rest.  Rows are plain data
(:class:`FlightResult`); :mod:`.flight_report` prints and plots them.
"""

from __future__ import annotations

import math
import time
from dataclasses import asdict, dataclass, field

import numpy as np

from ...api import Renderer
from ...cameras.camera import Camera
from ...cameras.framing import default_camera
from ...cameras.poses import orbit
from ...cameras.up import resolve_up
from ..evaluation.metrics import psnr
from .scale import rss_mb
from ...interactive.budget import Level
from ...interactive.draft import DraftFrame
from ...interactive.lod_cache import LodProvider
from ...interactive.session import Session
from ...interactive.stream_levels import streamed_session
from ...scene.splats import Scene
from ...scene.settings import RendererKind, RenderSettings
from ...renderers.registry import DEFAULT_RENDERER

#: The flight's phases (seconds): orbit until ORBIT_END, fly in until MOVE_END, then rest.
ORBIT_END = 5.0
MOVE_END = 8.0
#: Orbit speed (degrees a second) and the fly-in's start and end distances (framing distances).
ORBIT_DEG_S = 36.0
FLY_FROM, FLY_TO = 2.0, 1.0 / 3.0
#: Input events injected into refinements for the latency figure.
LATENCY_SAMPLES = 8
#: At most this many moving frames are scored (evenly spread): at 60 fps on a GPU the flight has
#: about 500, and each score draws the exact frame again (a full CPU sort: ~0.3 s at 6M splats).
MAX_SCORED = 160
#: A streamed flight's rest gives up on the exact frame after this many seconds (a safety limit:
#: a cut whose chunks do not fit the cache at once is gathered, as a headless frame is).
STREAM_REST_LIMIT_S = 300.0
#: Seconds a streamed rest sleeps while it waits for chunks (the loader threads need the cores).
STREAM_WAIT_S = 0.005


@dataclass
class FlightFrame:
    """One moving frame: ``t`` seconds into the flight, drawn at ``level`` in ``seconds``."""

    t: float
    seconds: float
    scale: float
    budget: int | None
    sh_degree: int | None
    splats: int
    psnr: float | None = None


@dataclass
class FlightResult:
    """One scene's flight (times in seconds)."""

    scene: str
    splats: int
    size: tuple[int, int]
    target_fps: float
    lod_seconds: float
    frames: list[FlightFrame] = field(default_factory=list)
    rest_to_exact: float = 0.0
    refine_steps: list[str] = field(default_factory=list)
    exact_seconds: float = 0.0
    latencies: list[float] = field(default_factory=list)
    exact_matches_render: bool = False
    #: The budget's correction to the model's cut error after the calibrations at rest, and
    #: those calibrations ("level: PSNR").
    cut_factor: float = 1.0
    calibrations: list[str] = field(default_factory=list)
    #: A streamed flight's samples, one a frame: ``t`` (seconds since the flight began),
    #: ``phase`` (moving, rest), ``resident_mb``, ``chunks_loaded``, ``rss_mb``; and whether
    #: its rest reached the exact frame (within :data:`STREAM_REST_LIMIT_S`).
    samples: list[dict] = field(default_factory=list)
    reached_exact: bool = True

    def fps(self) -> np.ndarray:
        return 1.0 / np.array([f.seconds for f in self.frames]) if self.frames else np.zeros(0)

    def summary(self) -> dict:
        fps = self.fps()
        psnrs = [f.psnr for f in self.frames if f.psnr is not None]
        finite = [p for p in psnrs if math.isfinite(p)]
        return {
            "scene": self.scene, "splats": self.splats, "size": list(self.size),
            "target_fps": self.target_fps, "frames": len(self.frames),
            "fps_median": float(np.median(fps)) if fps.size else 0.0,
            "fps_p10": float(np.percentile(fps, 10)) if fps.size else 0.0,
            "psnr_median": float(np.median(psnrs)) if psnrs else None,
            "psnr_min": float(min(finite)) if finite else None,
            "rest_to_exact": self.rest_to_exact, "exact_seconds": self.exact_seconds,
            "latency_median": float(np.median(self.latencies)) if self.latencies else None,
            "latency_max": float(max(self.latencies)) if self.latencies else None,
            "lod_seconds": self.lod_seconds, "exact_matches_render": self.exact_matches_render,
            "cut_factor": self.cut_factor, **self._stream_summary(),
        }

    def _stream_summary(self) -> dict:
        """A streamed flight's memory: resident chunks (MB, at most), chunks loaded, the
        process's resident set (MB) at the flight's start, end and most."""
        if not self.samples:
            return {}
        rss = [s["rss_mb"] for s in self.samples]
        return {"reached_exact": self.reached_exact,
                "resident_max_mb": max(s["resident_mb"] for s in self.samples),
                "chunks_loaded": self.samples[-1]["chunks_loaded"],
                "rss_start_mb": rss[0], "rss_end_mb": rss[-1], "rss_max_mb": max(rss)}

    def to_dict(self) -> dict:
        d = asdict(self)
        for f in d["frames"]:
            if f["psnr"] is not None and math.isinf(f["psnr"]):
                f["psnr"] = None   # JSON has no infinity (identical)
        return d


class Flight:
    """The scripted camera for one scene and image size (see the module doc); ``speed`` > 1
    flies the same path that many times faster (tests)."""

    def __init__(self, scene: Scene, width: int, height: int, speed: float = 1.0):
        self.speed = float(speed)
        self.base = default_camera(scene, width, height)
        lo, hi = scene.robust_bounds
        self.centre = 0.5 * (lo + hi)
        self.distance = float(np.linalg.norm(self.base.center - self.centre))
        path = scene.source.path if scene.source is not None else None
        self.up = resolve_up(None, path)[0]

    @property
    def move_end(self) -> float:
        """Seconds of movement (then rest)."""
        return MOVE_END / self.speed

    def camera(self, t: float) -> Camera:
        """The camera ``t`` seconds into the flight (after :attr:`move_end`: at rest)."""
        t = min(t * self.speed, MOVE_END)
        if t <= ORBIT_END:
            azimuth, distance = 180.0 + ORBIT_DEG_S * t, self.distance
        else:
            azimuth = 180.0 + ORBIT_DEG_S * ORBIT_END
            u = (t - ORBIT_END) / (MOVE_END - ORBIT_END)
            distance = self.distance * FLY_FROM * (FLY_TO / FLY_FROM) ** u
        return self.base.with_pose(orbit(self.centre, distance, azimuth, 20.0, self.up))


def _level_of(frame: FlightFrame) -> Level:
    return Level(frame.scale, frame.budget, frame.sh_degree)


def fly(renderer: Renderer, scene: Scene, name: str, width: int = 1280, height: int = 720,
        target_fps: float = 10.0, settings: RenderSettings | None = None,
        psnr_every: int = 1, log=print, speed: float = 1.0,
        exact_kind: RendererKind | str = DEFAULT_RENDERER, stream=None) -> FlightResult:
    """Fly over ``scene`` (see the module doc); ``psnr_every``: score every n-th moving frame
    (more apart where the flight has over :data:`MAX_SCORED`);
    ``speed``: fly the path that many times faster (tests); ``exact_kind``: the renderer of
    the exact frame at rest (the CPU renderer: as ``splatgl view --renderer cpu``), which is
    also what the moving frames are scored against.  ``stream``: fly over a level of detail
    streamed from disk instead (a :class:`~splatgl.lod.stream_view.StreamedScene`; ``scene``
    is then ignored), through the viewer's session over it (see the module doc)."""
    exact_kind = RendererKind(exact_kind)
    settings = settings or RenderSettings()
    scene = stream.framing if stream is not None else scene
    flight = Flight(scene, width, height, speed)
    t0 = time.perf_counter()
    if stream is None:
        lod = LodProvider(scene, scene.source.path if scene.source is not None else None)
        lod.wait()
        session = Session(renderer, scene, settings, 1.0 / target_fps, lod, exact_kind=exact_kind)
    else:
        session = streamed_session(renderer, stream, settings, 1.0 / target_fps)
    result = FlightResult(name, scene.count, (width, height), target_fps, time.perf_counter() - t0)
    try:
        _warm_up(session, flight)
        sample = None if stream is None else _sampler(stream, result)
        _moving(session, flight, result, sample)
        _rest(session, flight, result, sample,
              math.inf if stream is None else STREAM_REST_LIMIT_S / flight.speed)
        if stream is None:
            _latency(session, flight, result)
            result.calibrations = [f"{lv.describe()}: {p:.1f} dB" for lv, p in session.calibrations]
            _score(session, flight, result, psnr_every)
            rest = flight.camera(flight.move_end)
            exact = session.levels.read(_exact(session, rest))
            want = renderer.render(scene, rest, settings, exact_kind)
            result.exact_matches_render = bool(np.array_equal(exact, want))
        result.cut_factor = session.budget.cut_factor
    finally:
        session.release()
    s = result.summary()
    log(f"{name}: {s['frames']} moving frames, {s['fps_median']:.1f} fps median "
        f"(p10 {s['fps_p10']:.1f}), PSNR median {s['psnr_median'] or 0:.1f} dB, exact "
        f"{s['rest_to_exact']:.2f} s after rest, latency max {(s['latency_max'] or 0) * 1e3:.0f} ms")
    return result


def _sampler(stream, result: FlightResult):
    """A streamed flight's sampler: ``sample(phase)`` appends the resident memory, chunks
    loaded and the process's resident set to ``result.samples`` (at most every 0.1 s)."""
    start = time.perf_counter()

    def sample(phase: str) -> None:
        t = time.perf_counter() - start
        if result.samples and result.samples[-1]["phase"] == phase and t - result.samples[-1]["t"] < 0.1:
            return
        stats = stream.resident.stats
        result.samples.append({"t": t, "phase": phase, "resident_mb": stats.resident_bytes / 1e6,
                               "chunks_loaded": stats.loaded, "rss_mb": rss_mb()})
    return sample


def _warm_up(session: Session, flight: Flight) -> None:
    """What happens before a person moves the camera: the programs of every kind of level are
    compiled (not part of the flight), and the view rests at the start camera until exact, as
    a window opens (which also calibrates the cuts' quality for this scene)."""
    cam = flight.camera(0.0)
    for level in {session.budget.levels[0], session.budget.levels[-1], Level(0.5)}:
        session.levels.draw(cam, level)
    for i in range(3):
        session.frame(flight.camera(0.01 * (i + 1)))
    rest = flight.camera(0.03)
    while session.pending and not session.awaiting:   # a streamed scene: no wait for chunks
        session.frame(rest)


def _moving(session: Session, flight: Flight, result: FlightResult, sample=None) -> None:
    start = time.perf_counter()
    while (t := time.perf_counter() - start) < flight.move_end:
        frame = session.frame(flight.camera(t))
        lv = frame.level
        result.frames.append(FlightFrame(t, frame.seconds, lv.scale, lv.budget, lv.sh_degree,
                                         frame.splats))
        if sample is not None:
            sample("moving")


def _rest(session: Session, flight: Flight, result: FlightResult, sample=None,
          limit: float = math.inf) -> None:
    """At rest until the exact frame (``limit`` seconds at most: then
    :attr:`FlightResult.reached_exact` is False)."""
    cam = flight.camera(flight.move_end)
    start = time.perf_counter()
    while not session.exact:
        if time.perf_counter() - start > limit:
            result.reached_exact = False
            break
        frame = session.frame(cam)
        if frame is not None:
            result.refine_steps.append(frame.level.describe())
            if frame.level.exact:
                result.exact_seconds = frame.seconds
        elif session.awaiting:       # streamed chunks still coming: leave the cores to them
            time.sleep(STREAM_WAIT_S)
        if sample is not None:
            sample("rest")
    result.rest_to_exact = time.perf_counter() - start
    if sample is not None:
        sample("exact")


def _latency(session: Session, flight: Flight, result: FlightResult) -> None:
    """Input at a random moment of a refinement: seconds until the new camera's frame is done."""
    rng = np.random.default_rng(0)
    for k in range(LATENCY_SAMPLES):
        t = flight.move_end - 0.05 * (k + 1) / flight.speed
        cam = flight.camera(t)
        session.frame(cam)                       # a moving frame: refinement starts over
        expected = max(result.exact_seconds, 0.05)
        arrival = time.perf_counter() + rng.uniform(0.0, expected)
        pending = lambda: time.perf_counter() >= arrival  # noqa: E731
        while not session.exact and not pending():
            session.frame(cam, pending)
        while time.perf_counter() < arrival:     # refinement ended first: wait for the input
            time.sleep(0.001)
        session.frame(flight.camera(t - 0.02 / flight.speed))   # the input's frame
        result.latencies.append(time.perf_counter() - arrival)


def _score(session: Session, flight: Flight, result: FlightResult, every: int) -> None:
    levels = session.levels
    every = max(every, math.ceil(len(result.frames) / MAX_SCORED))
    for i, f in enumerate(result.frames):
        if i % every:
            continue
        level = _level_of(f)
        cam = flight.camera(f.t)
        exact = levels.read(_exact(session, cam))
        got = levels.read(levels.draw(cam, level)) if not level.exact or session.cpu_exact else exact
        f.psnr = float(psnr(got[..., :3], exact[..., :3]))


def _exact(session: Session, camera: Camera) -> DraftFrame:
    """The session's exact frame of ``camera``: the CPU renderer's or the quad path's."""
    if session.cpu_exact:
        return session.levels.draw_cpu(camera)
    return session.levels.draw(camera, Level())
