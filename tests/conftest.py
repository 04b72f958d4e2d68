"""Fixtures and hooks for the whole suite: the hypothesis profile, where the real scenes are,
headless OpenGL contexts (checked for GL errors around every test), and the markers derived
from fixtures.  Helpers that tests import live in ``helpers.py``."""

from __future__ import annotations

import os
from datetime import timedelta
from pathlib import Path

import pytest
from hypothesis import HealthCheck, settings

pytest.register_assert_rewrite("helpers")

from helpers import REPO  # noqa: E402 (after the rewrite hook)

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


def shared_scenes_dir() -> Path:
    """``$SPLATGL_SHARED_SCENES`` or ``../shared/scenes`` beside the repository."""
    env = os.environ.get("SPLATGL_SHARED_SCENES")
    return Path(env) if env else REPO.parent / "shared" / "scenes"


@pytest.fixture(scope="session")
def shared_scenes() -> Path:
    """The real scenes folder; tests using it skip with a reason where it is absent."""
    path = shared_scenes_dir()
    if not path.is_dir():
        pytest.skip(f"real scenes folder not found at {path} (set SPLATGL_SHARED_SCENES)")
    return path


@pytest.fixture
def artifacts_dir() -> Path:
    """Where tests dump got/expected/difference images on failure."""
    path = REPO / "test-artifacts"
    path.mkdir(exist_ok=True)
    return path


@pytest.fixture(scope="module")
def gl_renderer():
    """A :class:`splatgl.render.Renderer` on a headless context, shared by a test module.

    Skips the module where no OpenGL context can be made.  After the module, checks that no GL
    error was left pending.
    """
    from splatgl.errors import ContextError
    from splatgl.gl.context import make_current
    from splatgl.render import Renderer

    try:
        renderer = Renderer()
    except ContextError as exc:
        pytest.skip(f"no OpenGL context: {exc}")
    yield renderer
    make_current(renderer.ctx)  # other tests may have made their own contexts current
    error = renderer.ctx.error
    renderer.close()
    assert error == "GL_NO_ERROR", f"OpenGL error left pending: {error}"


@pytest.fixture(scope="module")
def ctx():
    """A bare headless context per module (for renderers built directly); checks that no GL
    error is left pending."""
    from splatgl.errors import ContextError
    from splatgl.gl.context import create_headless_context, make_current

    try:
        context = create_headless_context()
    except ContextError as exc:
        pytest.skip(f"no OpenGL context: {exc}")
    yield context
    make_current(context)
    error = context.error
    context.release()
    assert error == "GL_NO_ERROR", f"OpenGL error left pending: {error}"
