"""What many test modules share: the seeded random-scene factory, small scene builders, real
scene lookup, image checks and output parsing.

Test modules import these with ``from helpers import ...`` (pytest puts ``tests/`` on the path);
``conftest.py`` holds only fixtures and hooks, since pytest advises against importing it.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from splatgl.cameras.poses import orbit
from splatgl.cameras.view import View
from splatgl.constants import SH_C0, sh_coeff_count
from splatgl.scene.splats import Scene, SplatKind
from splatgl.scene.settings import RenderSettings
from splatgl.output.layers import BASE, Layer, with_layers

REPO = Path(__file__).resolve().parent.parent

#: Whether the tests' OpenGL is a GPU's rather than a software rasteriser's (llvmpipe, which
#: follows IEEE float32 step by step): set by the ``gl_renderer`` and ``ctx`` fixtures.
GPU_GL = False
#: A GPU's shader math fuses multiply-adds and approximates exp and reciprocals: values move by
#: a few ulps, which at the odd pixel flips a splat across the 1/255 alpha cut (a change of up
#: to 1/255 of its colour).  Measured on an H100 (driver 580.159): image errors up to 3.5e-3 on
#: one pixel in 10,000 (quad path: 1e-4 on 7% of pixels), depth keys off by one ulp, a mesh's
#: interpolated depth within 2.3e-4 relative (the rasteriser's sub-pixel snapping).
GPU_IMAGE_TOL = 4e-3
GPU_KEY_ULPS = 2
GPU_DEPTH_RTOL = 1e-3


def note_context(ctx) -> None:
    """Record whether ``ctx`` (the fixtures' context) runs on a GPU (:data:`GPU_GL`)."""
    from splatgl.gl.egl_devices import is_software_renderer

    global GPU_GL
    GPU_GL = not is_software_renderer(ctx.info.get("GL_RENDERER", ""))


def image_tol(tol: float) -> float:
    """A test's image tolerance where its context is llvmpipe; :data:`GPU_IMAGE_TOL` on a GPU."""
    return max(tol, GPU_IMAGE_TOL) if GPU_GL else tol


def needs_framebuffer_fetch(ctx) -> None:
    """Skip a test of the quad path's ordered layers (count, median depth, top id) on a driver
    without framebuffer fetch, where the quad path refuses them (tested on its own)."""
    from splatgl.renderers.quad_layers import FETCH_EXTENSION

    if FETCH_EXTENSION not in ctx.extensions:
        pytest.skip(f"{ctx.info.get('GL_RENDERER')} lacks {FETCH_EXTENSION} (quad ordered layers)")

#: Layouts for :func:`random_scene` (its keyword arguments).  ``IN_VIEW``: splats in front of an
#: identity camera (looking down +z, z about 2 to 6), small (scales ~exp(-2.3)), mixed
#: opacities; what the reference and tile renderer tests draw.
IN_VIEW = dict(center=(0.0, 0.0, 4.0), spread=(1.0, 0.8, 0.7), log_scale=(-2.3, 0.6),
               logit=(0.0, 2.0), sh_sd=0.4, wild_colors=0.0)
#: Splats around z 5 (2..8 within 3 sigma) in front of an identity camera, scales about 0.01..0.3
#: (the tile tests' 128 x 96 view).
IN_DEPTH = dict(center=(0.0, 0.0, 5.0), spread=(1.0, 0.75, 1.0), log_scale=(-2.9, 0.6),
                logit=(0.0, 2.0), sh_sd=0.5, wild_colors=0.0)
#: 2DGS surfels around the origin (sigma 0.6), scales ~exp(-2.6), mixed opacities (for orbit
#: cameras).
SURFELS = dict(kind=SplatKind.SURFEL_2D, center=(0.0, 0.0, 0.0), spread=0.6,
               log_scale=(-2.6, 0.5), logit=(0.5, 1.5), sh_sd=0.4, wild_colors=0.0)
#: A camera pose 3 units from the origin looking at ``SURFELS`` (azimuth 30, elevation 20).
SURFELS_POSE = orbit([0.0, 0.0, 0.0], 3.0, 30.0, 20.0)


def random_scene(n: int, seed: int = 0, degree: int = 0,
                 kind: SplatKind = SplatKind.GAUSSIAN_3D, *, center=0.0, spread=2.0,
                 log_scale: tuple[float, float] = (-4.0, 1.5),
                 logit: tuple[float, float] = (0.0, 3.0), sh_sd: float = 0.3,
                 wild_colors: float = 0.1) -> Scene:
    """``n`` seeded splats of raw values as a trainer writes them (the one scene factory).

    Means ``center + spread * N(0, 1)`` (``spread`` per axis or one number); unnormalised
    quaternions ``N(0, 1)^4``; log scales and opacity logits normal with (mean, sd)
    ``log_scale`` and ``logit``; SH coefficients ``N(0, sh_sd)`` up to ``degree``, and for the
    first ``wild_colors`` fraction of rows a DC term ``N(0, 4)``, colours far outside 0-1.  The
    defaults suit file round trips; the layouts above place splats for rendering.  ``kind``
    SURFEL_2D gives two scales per splat.
    """
    rng = np.random.default_rng(seed)
    means = np.asarray(center, np.float64) + np.asarray(spread, np.float64) * rng.standard_normal((n, 3))
    quats = rng.standard_normal((n, 4))
    nscale = 2 if kind is SplatKind.SURFEL_2D else 3
    log_scales = rng.normal(*log_scale, (n, nscale))
    logits = rng.normal(*logit, n)
    sh = rng.normal(0.0, sh_sd, (n, sh_coeff_count(degree), 3))
    wild = int(n * wild_colors)
    if wild:
        sh[:wild, 0] = rng.normal(0.0, 4.0, (wild, 3))
    return Scene(means, quats, log_scales, logits, sh, kind)


def scene_with_colors(means, quats, scales, opacities, rgb, kind=None) -> Scene:
    """A scene from activated values whose SH degree-0 colour seen from anywhere is ``rgb``
    (N, 3); ``kind`` defaults to 3DGS (pass SplatKind.SURFEL_2D with two scales)."""
    n = len(means)
    sh = np.zeros((n, 1, 3))
    sh[:, 0] = (np.asarray(rgb, float) - 0.5) / SH_C0
    return Scene.from_activated(np.asarray(means, float), np.asarray(quats, float),
                                np.asarray(scales, float), np.asarray(opacities, float), sh,
                                kind or SplatKind.GAUSSIAN_3D)


def shared_file(shared_scenes: Path, name: str) -> Path:
    """``shared_scenes / name``, skipping the test with the reason when that file is absent."""
    path = shared_scenes / name
    if not path.is_file():
        pytest.skip(f"{path} not present")
    return path


def save_failure_images(directory: Path, name: str, got, expected) -> str:
    """Dump got / expected / |difference| (x10) images; returns a note for assertion messages."""
    from splatgl.imagefiles.images import write_image

    diff = np.abs(np.asarray(got, np.float32) - np.asarray(expected, np.float32))
    paths = []
    for tag, img in (("got", got), ("expected", expected), ("diff_x10", diff * 10)):
        img = np.asarray(img, np.float32)
        if img.ndim == 2:
            img = np.repeat(img[..., None], 3, axis=-1)
        if img.shape[-1] == 3:
            img = np.concatenate([img, np.ones(img.shape[:2] + (1,), np.float32)], -1)
        path = directory / f"{name}_{tag}.exr"
        write_image(path, img)
        paths.append(str(path))
    return "images: " + ", ".join(paths)


def assert_stages_match_reference(got, proj, min_keys: int = 0) -> None:
    """The tile renderer's integer stages (``TileRenderer.debug_stages``) equal the NumPy
    reference's for the same projection: tiles touched, rectangles, emitted and sorted keys and
    values, and tile ranges, bit for bit."""
    from splatgl.reference import emit_keys, sort, tile_ranges

    np.testing.assert_array_equal(got.tiles_touched, proj.tiles_touched)
    np.testing.assert_array_equal(got.rect_min, proj.rect_min)
    np.testing.assert_array_equal(got.rect_max, proj.rect_max)
    keys, values = emit_keys(proj)
    assert len(keys) > min_keys  # the scene really spans many tiles
    if GPU_GL:  # depth bits within a few ulps (GPU_KEY_ULPS); tiles, splats and ranges exact
        _assert_keys_near(got.emitted_keys, keys)
        np.testing.assert_array_equal(got.emitted_values, values)
        sorted_keys, sorted_values = sort(keys, values)
        assert_sorted_keys_match(got.keys, got.values, sorted_keys, sorted_values)
        np.testing.assert_array_equal(got.ranges, tile_ranges(sorted_keys, proj.n_tiles))
        return
    np.testing.assert_array_equal(got.emitted_keys, keys)
    np.testing.assert_array_equal(got.emitted_values, values)
    keys, values = sort(keys, values)
    np.testing.assert_array_equal(got.keys, keys)
    np.testing.assert_array_equal(got.values, values)
    np.testing.assert_array_equal(got.ranges, tile_ranges(keys, proj.n_tiles))


def _assert_keys_near(got: np.ndarray, want: np.ndarray) -> None:
    """uint64 keys ``tile << 32 | depth bits``: tiles equal, depth bits within GPU_KEY_ULPS."""
    got, want = np.asarray(got, np.uint64), np.asarray(want, np.uint64)
    assert got.shape == want.shape
    np.testing.assert_array_equal(got >> np.uint64(32), want >> np.uint64(32))
    low = np.uint64(0xFFFFFFFF)
    ulps = np.abs((got & low).astype(np.int64) - (want & low).astype(np.int64))
    assert ulps.max(initial=0) <= GPU_KEY_ULPS, f"depth keys {ulps.max()} ulps apart"


def assert_sorted_keys_match(got_keys, got_values, keys, values) -> None:
    """Sorted (keys, values) equal the reference's; on a GPU (:data:`GPU_GL`) the depth bits may
    be a few ulps off, which can swap neighbours: the i-th smallest keys stay within those ulps
    and each tile holds the same splats."""
    if not GPU_GL:
        np.testing.assert_array_equal(got_keys, keys)
        np.testing.assert_array_equal(got_values, values)
        return
    got_keys, keys = np.asarray(got_keys, np.uint64), np.asarray(keys, np.uint64)
    assert (got_keys[1:] >= got_keys[:-1]).all()
    _assert_keys_near(got_keys, keys)
    tiles, want_tiles = got_keys >> np.uint64(32), keys >> np.uint64(32)
    np.testing.assert_array_equal(np.asarray(got_values)[np.lexsort((got_values, tiles))],
                                  np.asarray(values)[np.lexsort((values, want_tiles))])


def tile_and_reference(ctx, scene, camera, settings):
    """(tile renderer's RenderOutput, float32 NumPy reference image) of one view; the tile
    renderer is released afterwards."""
    from splatgl.reference import render_reference
    from splatgl.renderers.tile import TileRenderer

    renderer = TileRenderer(ctx, scene, settings)
    try:
        got = renderer.render(View.of(camera, settings, scene), with_layers(Layer.DEPTH))
    finally:
        renderer.release()
    return got, render_reference(scene, camera, settings, np.float32)


def summary_counts(out: str, unit: str) -> tuple[list[int], int]:
    """Per-worker counts and the total of the summary that ``--workers`` / ``--executor ray``
    print (``worker i (host, pid P): N unit in S s, R unit/s`` ... ``total: N unit in ...``)."""
    lines = [line for line in out.splitlines() if line.startswith(("worker ", "total: "))]
    assert lines and all(f" {unit} in " in line for line in lines), out
    workers = [int(line.split("): ")[1].split()[0]) for line in lines if line.startswith("worker ")]
    totals = [int(line.split()[1]) for line in lines if line.startswith("total: ")]
    assert len(totals) == 1, out
    return workers, totals[0]


# --- damaged files (tests/test_formats_fuzz*.py) ----------------------------------------------

#: A load of a damaged file may hold at most this many bytes of Python / NumPy memory per byte
#: of the file, plus MEMORY_SLACK, at its peak: a damaged header count must be refused, not
#: allocated.  Undamaged files peak at 2.2-17.9 bytes per byte (compressed PLY and SPZ highest;
#: the 69-byte minimal SPZ at 52 KB, inside the slack).  Memory, unlike time, does not change
#: with the load on the machine.
MEMORY_PER_BYTE = 32
MEMORY_SLACK = 4 << 20


def refused(capsys, tmp_path: Path, argv, line: str) -> None:
    """The command ``argv`` exits 2 with exactly ``line`` on stderr, nothing on stdout, and
    leaves ``tmp_path`` as it was (no output, no temporary)."""
    from splatgl.cli import main

    before = sorted(p.name for p in tmp_path.iterdir())
    rc = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    assert (rc, out, err) == (2, "", line + "\n")
    assert sorted(p.name for p in tmp_path.iterdir()) == before


def truncations(size: int, cases: int, rng) -> list[int]:
    """Fixed lengths (empty, magic only, header-sized) and ``cases`` random ones, all < size."""
    fixed = [0, 1, 4, 15, 16, 100, size // 2, size - 1]
    return sorted({n for n in fixed if n < size} | set(rng.integers(0, size, cases).tolist()))


def corruptions(data: bytes, cases: int, rng) -> list[bytes]:
    """Copies of ``data`` with 1-8 random bytes replaced, in the first 256 bytes (headers) for
    half of the cases and anywhere for the rest; plus one with a 0xff run over a header count."""
    out = []
    for case in range(cases):
        buf = bytearray(data)
        span = min(len(buf), 256) if case % 2 == 0 else len(buf)
        for pos in rng.integers(0, span, rng.integers(1, 9)):
            buf[pos] = int(rng.integers(0, 256))
        out.append(bytes(buf))
    for start in (8, 12):  # SPZ numPoints / ksplat counts / PLY header text
        buf = bytearray(data)
        buf[start:start + 4] = b"\xff\xff\xff\xff"
        out.append(bytes(buf))
    return out


def assert_clean_line(message: str, what: str) -> None:
    """One printable line of bounded length: no control characters, no NUL runs."""
    from splatgl.formats._messages import MESSAGE_LIMIT

    assert message.isprintable(), f"{what}: control characters in {message[:200]!r}"
    assert len(message) <= MESSAGE_LIMIT, f"{what}: {len(message)}-character message"


def check_case(read, path: Path, data: bytes, what: str, must_fail: bool = False):
    """Load ``data`` as ``path``: a scene, or a SceneFormatError with one clean line; never
    another exception, a NumPy warning or a peak of more than MEMORY_PER_BYTE bytes per byte
    of ``data`` (plus MEMORY_SLACK).  Returns the scene, or the message."""
    import tracemalloc
    import warnings

    from splatgl.errors import SceneFormatError

    path.write_bytes(data)
    result = None
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        tracing = tracemalloc.is_tracing()
        if tracing:
            tracemalloc.reset_peak()
        else:
            tracemalloc.start()
        base = tracemalloc.get_traced_memory()[0]
        try:
            result = read(path)
        except SceneFormatError as exc:
            result = str(exc)
            assert_clean_line(result, what)
        except Exception as exc:  # noqa: BLE001 - the point of the test
            pytest.fail(f"{what}: {type(exc).__name__}: {exc}")
        finally:
            peak = tracemalloc.get_traced_memory()[1] - base
            if not tracing:
                tracemalloc.stop()
    limit = MEMORY_PER_BYTE * len(data) + MEMORY_SLACK
    assert peak <= limit, f"{what}: peak memory {peak} bytes > {limit} for a {len(data)}-byte file"
    assert not [w for w in caught if issubclass(w.category, RuntimeWarning)], \
        f"{what}: warnings {[str(w.message) for w in caught]}"
    if must_fail:
        assert isinstance(result, str), f"{what}: loaded without an error"
    return result


# --- signals mid-run ---------------------------------------------------------------------------


def start_gated(argv: list[str], frames: int, processes: int = 1):
    """Start ``python -m splatgl *argv`` with the frame gate (``frame_gate/sitecustomize.py``):
    each rendering process (the command itself, or each of its ``processes`` workers) writes
    ``frames`` frames and then waits.  Returns the process once all of them wait, so a signal
    sent then (:func:`signal_and_wait`) always lands mid-run with exactly those frames on disk.
    The command runs in its own session, so that a failed test can kill all of it."""
    import os
    import subprocess
    import sys

    gate = str(Path(__file__).parent / "frame_gate")
    env = dict(os.environ, SPLATGL_TEST_GATE=str(frames),
               PYTHONPATH=os.pathsep.join(p for p in (gate, os.environ.get("PYTHONPATH")) if p))
    proc = subprocess.Popen([sys.executable, "-m", "splatgl", *argv], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, env=env, start_new_session=True)
    for _ in range(processes):
        line = proc.stdout.readline()  # blocks until a process waits at the gate (or all exit)
        if not line.startswith("gate "):
            _, err = _kill_session(proc)
            pytest.fail(f"no process reached the frame gate: {line!r}; stderr: {err[-2000:]}")
    return proc


def signal_and_wait(proc, signum: int, hang_guard: float = 120.0) -> tuple[str, str]:
    """Send ``signum`` to ``proc`` and return its (stdout, stderr) once it exits.  It should
    exit at once; if it has not after ``hang_guard`` seconds (a hang, not slowness), kill its
    whole session and fail."""
    import subprocess

    proc.send_signal(signum)
    try:
        return proc.communicate(timeout=hang_guard)
    except subprocess.TimeoutExpired:
        _, err = _kill_session(proc)
        pytest.fail(f"still running {hang_guard:.0f} s after signal {signum}; stderr: {err[-2000:]}")


def _kill_session(proc) -> tuple[str, str]:
    import os
    import signal

    try:
        os.killpg(proc.pid, signal.SIGKILL)  # the command and any worker it started
    except ProcessLookupError:  # not a session of its own
        proc.kill()
    return proc.communicate()


# ------------------------------------------------------------------ stages called directly
def view_of(camera, scene, settings: RenderSettings | None = None) -> View:
    """The :class:`View` of ``camera`` for ``scene`` under ``settings`` (default RenderSettings())."""
    return View.of(camera, settings or RenderSettings(), scene)


def project(scene, camera, settings: RenderSettings | None = None, dtype=np.float32, options=None):
    """The reference's first stage for ``camera`` (:func:`splatgl.reference.stages.project`)."""
    settings = settings or RenderSettings()
    from splatgl.reference.stages import project as reference_project

    return reference_project(scene, View.of(camera, settings, scene), settings, dtype, options)


def view_for(renderer, camera) -> View:
    """The view of ``camera`` built from ``renderer``'s own scene and settings."""
    return View.of(camera, renderer.options, renderer.scene)


def draw(renderer, camera, depth: bool = False, **options):
    """``renderer.render`` (a quad, tile or level-of-detail renderer) of ``camera``'s view
    (:func:`view_for`), with the depth layer when ``depth``: a RenderOutput.  ``options`` go to
    ``render`` (``on_batch``)."""
    layers = with_layers(Layer.DEPTH) if depth else BASE
    return renderer.render(view_for(renderer, camera), layers, **options)


def stream_lod_file(tmp_path: Path, n: int = 3000, seed: int = 0, coeffs: int = 4,
                    log_scale: float = -3.5) -> Path:
    """A ``.lod.ply`` of ``n`` random splats (``coeffs`` SH coefficients: 4 = SH1; log-scales
    about ``log_scale``) in the unit cube (branching 4) under ``tmp_path``: the small level of
    detail the streaming tests read by chunks."""
    from splatgl.formats import load_scene, ply_write
    from splatgl.lod.build import build_hierarchy
    from splatgl.lod.io import write_lod

    rng = np.random.default_rng(seed)
    scene = Scene(rng.uniform(-1, 1, (n, 3)), rng.normal(size=(n, 4)),
                  rng.normal(log_scale, 0.4, (n, 3)), rng.normal(1, 1, n),
                  rng.normal(0, 0.3, (n, coeffs, 3)))
    ply_write.write(tmp_path / "s.ply", scene)
    path = tmp_path / "s.lod.ply"
    write_lod(path, build_hierarchy(load_scene(tmp_path / "s.ply"), 4))
    return path


def compile_lib_check(ctx, folder: Path, libs, source: str):
    """A compute shader of ``source`` (GLSL that includes ``lib/<name>`` for each of ``libs``,
    copied from the shader library into ``folder``), for the library's own tests."""
    from splatgl.gl.shaders import preprocess, shader_dir

    (folder / "lib").mkdir()
    for lib in libs:
        (folder / "lib" / lib).write_text((shader_dir() / "lib" / lib).read_text())
    (folder / "check.comp").write_text(source)
    return ctx.compute_shader(preprocess("check.comp", root=folder).text)


def stream_camera(z: float, x: float = 0.0):
    """A 96x64, 50-degree camera at ``(x, 0, z)`` looking at the origin (the streaming tests')."""
    from splatgl.cameras.camera import Camera
    from splatgl.cameras.poses import look_at

    return Camera.from_fov(96, 64, 50.0, look_at(np.array([x, 0.0, z]), np.zeros(3)))


class GatedChunks:
    """A :class:`~splatgl.lod.stream.LazyChunks` whose loads wait for ``gate`` (an Event) once
    ``gated`` is set: the streaming tests hold chunk arrivals back with it."""

    def __init__(self, inner):
        import threading

        self.inner, self.gate, self.gated = inner, threading.Event(), False
        self.rows, self.nodes, self.count = inner.rows, inner.nodes, inner.count

    def estimate(self, chunk):
        return self.inner.estimate(chunk)

    def load(self, chunk):
        if self.gated:
            self.gate.wait(10)
        return self.inner.load(chunk)


#: Every shader stage source compiled in this test process, by its text's SHA-1: (the stage's
#: file extension, the stage file, the preprocessed text) (:func:`record_compiled_shaders`).
COMPILED_SHADERS: dict[str, tuple[str, str, str]] = {}


def record_compiled_shaders() -> None:
    """Keep every stage source :class:`splatgl.gl.shaders.ProgramCache` compiles from now on in
    :data:`COMPILED_SHADERS` (once per process; the compile itself is unchanged)."""
    import hashlib

    from splatgl.gl import shaders

    compile_ = shaders.ProgramCache._compile
    if getattr(compile_, "records", False):
        return
    ext = {"compute": "comp", "vertex": "vert", "fragment": "frag"}

    def recording(self, kind, sources):
        for stage, source in sources.items():
            digest = hashlib.sha1(source.text.encode()).hexdigest()
            COMPILED_SHADERS.setdefault(digest, (ext[stage], source.files[0], source.text))
        return compile_(self, kind, sources)

    recording.records = True
    shaders.ProgramCache._compile = recording
