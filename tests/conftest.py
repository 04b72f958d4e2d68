"""Fixtures and hooks for the whole suite: the hypothesis profile, where the real scenes are,
headless OpenGL contexts (checked for GL errors around every test), and the markers derived
from fixtures.  Helpers that tests import live in ``helpers.py``."""

from __future__ import annotations

import contextlib
import os
import shutil
import signal
import subprocess
from datetime import timedelta
from pathlib import Path

import pytest
from hypothesis import HealthCheck, settings

pytest.register_assert_rewrite("helpers")

import helpers  # noqa: E402 (after the rewrite hook)
from helpers import REPO  # noqa: E402

# Tests live in one folder per package they test (tests/<package>/test_*.py); a few import each
# other's constants and fixtures by module name (``from test_compare import MIN_PSNR``), so every
# test folder is on sys.path, as the one flat folder was.
import sys as _sys  # noqa: E402

for _folder in sorted(Path(__file__).parent.iterdir()):
    if _folder.is_dir() and _folder.name not in ("data", "frame_gate", "__pycache__") \
            and str(_folder) not in _sys.path:
        _sys.path.append(str(_folder))

# Hypothesis: every run draws the same examples ("ci", the default): derandomised (examples
# follow from each test's source), no example database (earlier failures do not change what
# runs), and no timing health check.  The deadline only catches an example 100x slower than the
# slowest one measured (0.33 s, a GPU LOD fly-in); tests set only max_examples.
# HYPOTHESIS_PROFILE=explore draws new random examples each run, for looking for bugs.
settings.register_profile("ci", derandomize=True, database=None, deadline=timedelta(seconds=30),
                          suppress_health_check=[HealthCheck.too_slow], print_blob=True)
settings.register_profile("explore", derandomize=False, deadline=None,
                          suppress_health_check=[HealthCheck.too_slow])
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "ci"))

# `--renderer auto` (render, render --path, view) draws with the CPU renderer on a software
# OpenGL device only where numba's on-disk cache holds its kernels: pinned to the quad path for
# the suite (and the processes it starts), so that no test depends on whether that cache is
# warm.  Tests of the auto choice itself unset it (tests/renderers/test_renderer_auto.py; docs/testing.md).
os.environ["SPLATGL_RENDERER_AUTO"] = "quad"


def shared_scenes_dir() -> Path:
    """``$SPLATGL_SHARED_SCENES`` or ``../shared/scenes`` beside the repository (the library's
    one lookup, from the repository root whatever the working directory)."""
    from splatgl.measure.bench.real_scenes import shared_scenes_dir as lookup

    return lookup(REPO)


def pytest_configure(config) -> None:
    """A run started with SIGINT ignored (a background job of a non-interactive shell, nohup)
    would hand that on to every process the tests start, and the Ctrl-C tests would wait for an
    interrupt that never comes: give this process Python's usual handler, which its children
    do not inherit."""
    if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
        signal.signal(signal.SIGINT, signal.default_int_handler)


def pytest_collection_modifyitems(items) -> None:
    """Mark ``shared`` every test that needs the real scenes (directly or through a fixture);
    run the tests marked ``last`` after all others (stable: each keeps its place otherwise)."""
    for item in items:
        if "shared_scenes" in getattr(item, "fixturenames", ()):
            item.add_marker(pytest.mark.shared)
    items.sort(key=lambda item: item.get_closest_marker("last") is not None)


# Every shader stage this process compiles is kept (helpers.COMPILED_SHADERS) for
# tests/gl/test_glsl_portable.py, which hands them to glslang, a second GLSL front-end.
helpers.record_compiled_shaders()


@pytest.fixture(scope="session")
def shared_scenes() -> Path:
    """The real scenes folder; tests using it skip with a reason where it is absent."""
    path = shared_scenes_dir()
    if not path.is_dir():
        pytest.skip(f"real scenes folder not found at {path} (set SPLATGL_SHARED_SCENES)")
    return path


@pytest.fixture(scope="session")
def compiled_kernels():
    """The compiled cull and cut kernels (:mod:`splatgl.order.kernels`) loaded, or None without
    numba.  A fresh checkout compiles them (10-40 s on a slow machine): a Hypothesis test asks
    for this fixture so that the compile happens outside its examples, whose 30 s deadline
    would otherwise time it (and report the test as flaky when the rerun is fast)."""
    from splatgl.order import kernels

    return kernels.kernel(wait=True) if kernels.installed() else None


@pytest.fixture
def full_disk():
    """``with full_disk(n):`` every file this process writes stops growing at ``n`` bytes, as on a
    disk that fills up: writes past it fail (EFBIG) and C libraries that ignore their write
    errors leave a file cut short.  Deterministic and unprivileged (RLIMIT_FSIZE with SIGXFSZ
    ignored, restored afterwards); skips where the platform lacks it."""
    resource = pytest.importorskip("resource", reason="RLIMIT_FSIZE needs the resource module (POSIX)")
    if not hasattr(signal, "SIGXFSZ"):
        pytest.skip("no SIGXFSZ on this platform")

    @contextlib.contextmanager
    def limit(nbytes: int):
        soft, hard = resource.getrlimit(resource.RLIMIT_FSIZE)
        old = signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
        resource.setrlimit(resource.RLIMIT_FSIZE, (nbytes, hard))
        try:
            yield
        finally:
            resource.setrlimit(resource.RLIMIT_FSIZE, (soft, hard))
            signal.signal(signal.SIGXFSZ, old)

    return limit


@pytest.fixture
def artifacts_dir() -> Path:
    """Where tests dump got/expected/difference images on failure."""
    path = REPO / "test-artifacts"
    path.mkdir(exist_ok=True)
    return path


@pytest.fixture(scope="module")
def gl_renderer():
    """A :class:`splatgl.api.Renderer` on a headless context, shared by a test module.

    Skips the module where no OpenGL context can be made.  Every test using it is checked for
    GL errors (:func:`gl_error_check`).
    """
    from splatgl.errors import ContextError
    from splatgl.api import Renderer

    try:
        renderer = Renderer()
    except ContextError as exc:
        pytest.skip(f"no OpenGL context: {exc}")
    helpers.note_context(renderer.ctx)
    yield renderer
    renderer.close()


@pytest.fixture(scope="module")
def ctx():
    """A bare headless context per module (for renderers built directly); every test using it
    is checked for GL errors (:func:`gl_error_check`)."""
    from splatgl.errors import ContextError
    from splatgl.gl.context import create_headless_context

    try:
        context = create_headless_context()
    except ContextError as exc:
        pytest.skip(f"no OpenGL context: {exc}")
    helpers.note_context(context)
    yield context
    context.release()


#: The fixtures whose OpenGL context several tests share.
SHARED_GL_FIXTURES = ("gl_renderer", "ctx")


def _gl_errors(context) -> list[str]:
    """Every GL error pending on ``context`` (reading one clears it), oldest first."""
    from splatgl.gl.context import make_current

    make_current(context)  # other tests may have made their own contexts current
    errors = []
    while len(errors) < 8 and (error := context.error) != "GL_NO_ERROR":
        errors.append(error)
    return errors


@pytest.fixture(autouse=True)
def gl_error_check(request):
    """Around every test that uses a shared context: no GL error pending before it (left by a
    fixture) or after it, so an error fails the test that made it, not a later test or the
    module's teardown (moderngl's own suite checks every test the same way)."""
    names = [name for name in SHARED_GL_FIXTURES if name in request.fixturenames]
    contexts = [getattr(value, "ctx", value) for value in map(request.getfixturevalue, names)]
    for context in contexts:
        if errors := _gl_errors(context):
            pytest.fail(f"OpenGL errors pending before the test: {', '.join(errors)}")
    yield
    for context in contexts:
        if errors := _gl_errors(context):
            pytest.fail(f"OpenGL errors left by the test: {', '.join(errors)}")


# ------------------------------------------------------------------ windows (Xvfb)
#: The Xvfb binary for window tests (None: they skip).
XVFB = "/usr/bin/Xvfb" if Path("/usr/bin/Xvfb").exists() else shutil.which("Xvfb")


def _die_with_parent() -> None:
    """In the Xvfb child: get SIGTERM when the test process dies (even by a crash), so a
    failed run leaves no server behind (Linux prctl PR_SET_PDEATHSIG)."""
    try:
        import ctypes
        import signal

        ctypes.CDLL(None, use_errno=True).prctl(1, signal.SIGTERM, 0, 0, 0)
    except Exception:
        pass


@pytest.fixture(scope="session")
def xvfb_display():
    """A private Xvfb server; DISPLAY points at it for the session, and it is killed after.

    Xvfb picks a free display itself and writes its number to a pipe once it accepts clients
    (``-displayfd``): no polling for its socket, no guessed display number that another test
    run could take at the same moment.
    """
    if XVFB is None:
        pytest.skip("Xvfb not installed (Debian package xvfb): cannot open windows headlessly")
    read_fd, write_fd = os.pipe()
    # -noreset: without it the server resets when its last client leaves, and a viewer opened
    # right after another one closed can fail to connect during the reset.
    proc = subprocess.Popen([XVFB, "-displayfd", str(write_fd), "-screen", "0", "1280x1024x24",
                             "-nolisten", "tcp", "-noreset"], stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL, pass_fds=(write_fd,),
                            preexec_fn=_die_with_parent)
    os.close(write_fd)
    with os.fdopen(read_fd) as ready:
        number = ready.readline().strip()  # blocks until the server is up, or it exited
    if not number.isdigit():
        proc.kill()
        pytest.skip(f"Xvfb did not start (exit status {proc.wait()})")
    n = int(number)
    old = os.environ.get("DISPLAY")
    os.environ["DISPLAY"] = f":{n}"
    import glfw

    if not glfw.init():
        proc.kill()
        pytest.skip(f"glfw cannot initialise on Xvfb :{n}")
    glfw.terminate()
    yield f":{n}"
    if old is None:
        os.environ.pop("DISPLAY", None)
    else:
        os.environ["DISPLAY"] = old
    proc.terminate()
    proc.wait(timeout=10)
