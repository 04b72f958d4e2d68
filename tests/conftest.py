"""Shared fixtures: where the real scenes are, and a headless OpenGL context."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parent.parent


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
