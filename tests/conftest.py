"""Shared fixtures: where the real scenes are, and a headless OpenGL context."""

from __future__ import annotations

import contextlib
import os
import signal
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parent.parent


def shared_scenes_dir() -> Path:
    """``$SPLATGL_SHARED_SCENES`` or ``../shared/scenes`` beside the repository (the library's
    one lookup, from the repository root whatever the working directory)."""
    from splatgl.bench.real_scenes import shared_scenes_dir as lookup

    return lookup(REPO)


@pytest.fixture(scope="session")
def shared_scenes() -> Path:
    """The real scenes folder; tests using it skip with a reason where it is absent."""
    path = shared_scenes_dir()
    if not path.is_dir():
        pytest.skip(f"real scenes folder not found at {path} (set SPLATGL_SHARED_SCENES)")
    return path


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


def save_failure_images(directory: Path, name: str, got, expected) -> str:
    """Dump got / expected / |difference| (x10) images; returns a note for assertion messages."""
    import numpy as np

    from splatgl.image_io import write_image

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


def scene_with_colors(means, quats, scales, opacities, rgb, kind=None):
    """A scene from activated values whose SH degree-0 colour seen from anywhere is ``rgb``
    (N, 3); ``kind`` defaults to 3DGS (pass SplatKind.SURFEL_2D with two scales)."""
    import numpy as np

    from splatgl.constants import SH_C0
    from splatgl.scene import Scene, SplatKind

    n = len(means)
    sh = np.zeros((n, 1, 3))
    sh[:, 0] = (np.asarray(rgb, float) - 0.5) / SH_C0
    return Scene.from_activated(np.asarray(means, float), np.asarray(quats, float),
                                np.asarray(scales, float), np.asarray(opacities, float), sh,
                                kind or SplatKind.GAUSSIAN_3D)


def assert_stages_match_reference(got, proj, min_keys: int = 0) -> None:
    """The tile renderer's integer stages (``TileRenderer.debug_stages``) equal the NumPy
    reference's for the same projection: tiles touched, rectangles, emitted and sorted keys and
    values, and tile ranges, bit for bit."""
    import numpy as np

    from splatgl.reference import emit_keys, sort, tile_ranges

    np.testing.assert_array_equal(got.tiles_touched, proj.tiles_touched)
    np.testing.assert_array_equal(got.rect_min, proj.rect_min)
    np.testing.assert_array_equal(got.rect_max, proj.rect_max)
    keys, values = emit_keys(proj)
    assert len(keys) > min_keys  # the scene really spans many tiles
    np.testing.assert_array_equal(got.emitted_keys, keys)
    np.testing.assert_array_equal(got.emitted_values, values)
    keys, values = sort(keys, values)
    np.testing.assert_array_equal(got.keys, keys)
    np.testing.assert_array_equal(got.values, values)
    np.testing.assert_array_equal(got.ranges, tile_ranges(keys, proj.n_tiles))


def tile_and_reference(ctx, scene, camera, settings):
    """(tile renderer's RenderOutput, float32 NumPy reference image) of one view; the tile
    renderer is released afterwards."""
    import numpy as np

    from splatgl.reference import render_reference
    from splatgl.tile import TileRenderer

    renderer = TileRenderer(ctx, scene, settings)
    try:
        got = renderer.render_layers(camera)
    finally:
        renderer.release()
    return got, render_reference(scene, camera, settings, np.float32)


def shared_file(shared_scenes: Path, name: str) -> Path:
    """``shared_scenes / name``, skipping the test with the reason when that file is absent."""
    path = shared_scenes / name
    if not path.is_file():
        pytest.skip(f"{path} not present")
    return path


def summary_counts(out: str, unit: str) -> tuple[list[int], int]:
    """Per-worker counts and the total of the summary that ``--workers`` / ``--executor ray``
    print (``worker i (host, pid P): N unit in S s, R unit/s`` ... ``total: N unit in ...``)."""
    lines = [line for line in out.splitlines() if line.startswith(("worker ", "total: "))]
    assert lines and all(f" {unit} in " in line for line in lines), out
    workers = [int(line.split("): ")[1].split()[0]) for line in lines if line.startswith("worker ")]
    totals = [int(line.split()[1]) for line in lines if line.startswith("total: ")]
    assert len(totals) == 1, out
    return workers, totals[0]
