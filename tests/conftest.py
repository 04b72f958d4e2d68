"""Shared fixtures: where the real scenes are, and a headless OpenGL context."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

pytest.register_assert_rewrite("helpers")

from helpers import REPO  # noqa: E402 (after the rewrite hook)


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
