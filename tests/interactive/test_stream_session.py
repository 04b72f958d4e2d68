"""The viewer's frame-time budget over a level of detail streamed from disk (issue 41 items 3
and 6): splatgl.interactive.stream_levels (the session ``view --memory`` and ``bench --scale
--lod``'s flight run) and the resident set's room for a new view."""

from __future__ import annotations

import time

import numpy as np
import pytest

from splatgl.interactive.budget import EXACT, Level
from splatgl.interactive.stream_levels import StreamedLevels, streamed_session
from splatgl.lod.lazy import LazyLod
from splatgl.lod.selection import LodSettings
from splatgl.lod.stream import LazyChunks, ResidentSet
from splatgl.scene.settings import EarlyStop, RenderSettings

from helpers import GatedChunks, stream_camera, stream_lod_file

SETTINGS = RenderSettings(near=0.01, early_stop=EarlyStop.OFF)


def tiny_lod(folder, n: int = 3000, seed: int = 0):
    """A random ``n``-splat SH0 scene's level of detail (branching 4) at ``folder``/s.lod.ply."""
    return stream_lod_file(folder, n, seed, coeffs=1, log_scale=-4.0)


_camera = stream_camera


_Gated = GatedChunks


def _until(test, seconds: float = 10.0) -> bool:
    end = time.perf_counter() + seconds
    while not test():
        if time.perf_counter() > end:
            return False
        time.sleep(0.005)
    return True


def test_a_full_resident_set_makes_room_for_a_new_view(tmp_path):
    """Once one view's chunks fill the budget, another view's cut still completes: only the
    chunks of the cut asked for are kept, the others are evicted for it (every resident chunk
    was kept, and a moved viewer never refined again)."""
    path = tiny_lod(tmp_path)
    with LazyLod(path) as lazy:
        chunks = LazyChunks(lazy, 64)
        leaves = lazy.level_size(0)
        half = (leaves // 2) // 64 * 64
        budget = int(sum(chunks.estimate(c) for c in range(chunks.count)) * 0.6)
        with ResidentSet(chunks, budget, lazy.offsets, lazy.branching) as resident:
            resident.load_pinned()
            for rows in (np.arange(half), np.arange(half, leaves)):   # disjoint leaf chunks
                assert _until(lambda: resident.resident_cut(rows, None)[2]), resident.stats
            assert resident.stats.evicted > 0
            assert resident.stats.resident_bytes <= budget


def cache_plan(cache: int):
    """A stream plan whose chunk cache is ``cache`` bytes and whose frame is not capped (tests:
    a tiny scene streams under a cache smaller than itself)."""
    from splatgl.lod.budget import StreamPlan

    return StreamPlan(budget=cache, held=0, reserve=0, cache=cache, frame=1 << 40, per_splat=100)


def _stream(tmp_path, memory: int = 1 << 20, gated: bool = False):
    from splatgl.lod.stream_view import StreamedScene

    path = tiny_lod(tmp_path)
    lazy = LazyLod(path)
    chunks = _Gated(LazyChunks(lazy, 64))
    stream = StreamedScene(path, LodSettings(), memory, chunks=chunks, plan=cache_plan(memory))
    chunks.gated = gated   # after the pinned top levels are in
    return stream, chunks, lazy


def test_session_over_a_streamed_scene_waits_for_chunks_then_is_exact(tmp_path, gl_renderer):
    """The viewer's session over a streamed scene: a frame drawn short of chunks is not exact
    and waits (``awaiting``: no draw until a chunk arrives); once every chunk is in, the frame
    at rest is exact and is the exact cut's image (the one a screenshot draws)."""
    stream, chunks, lazy = _stream(tmp_path, gated=True)
    session = streamed_session(gl_renderer, stream, SETTINGS, 10.0)   # a long budget: exact moves
    try:
        camera = _camera(1.6, 0.3)
        first = session.frame(camera)
        assert first is not None and first.level == EXACT
        assert not session.exact and session.awaiting and session.status == "moving"
        assert session.frame(camera) is None and session.status == "refining"  # nothing arrived
        chunks.gate.set()
        assert _until(lambda: stream.generation > 0)
        drawn = []
        assert _until(lambda: (drawn.append(session.frame(camera)), session.exact)[1], 20)
        assert any(d is not None for d in drawn) and not session.awaiting
        assert session.status == "exact" and stream.complete
        got = session.levels.read(session.shown)
        want = gl_renderer.render(stream.exact_scene(camera, SETTINGS), camera, SETTINGS)
        assert np.array_equal(got, want)
    finally:
        session.release()
        stream.close()
        lazy.close()


def test_budgeted_levels_draw_the_budgets_cut_of_what_is_resident(tmp_path, gl_renderer):
    """A level with a splat budget draws at most that many nodes (the budget's cut), a
    full-detail level the view's cut; each kind of level keeps one renderer, replaced (and
    released) when its scene changes; a cut for another view (a moving frame) releases the
    full detail of the last (its upload is not held through a movement), one for the same
    view (the calibration at rest) keeps it."""
    stream, chunks, lazy = _stream(tmp_path, memory=4 << 20)
    levels = StreamedLevels(gl_renderer, stream, SETTINGS)
    try:
        camera = _camera(1.6, 0.3)
        assert levels.has_lod
        cut = levels.draw(camera, Level(1.0, 200))
        assert 0 < cut.splats <= 200
        assert _until(lambda: (levels.draw(camera, EXACT), levels.complete)[1], 20)
        full = levels.draw(camera, EXACT)
        assert full.splats > 200 and levels.complete
        assert len(levels._paths) == 2
        before = levels._paths[(True, None)][1]
        levels.draw(_camera(2.5, -0.2), EXACT)   # another view's cut: a new scene
        assert levels._paths[(True, None)][1] is not before and len(levels._paths) == 2
        full = levels._paths[(True, None)][1]
        levels.draw(_camera(2.5, -0.2), Level(1.0, 200))   # the same view: kept
        assert levels._paths[(True, None)][1] is full
        levels.draw(_camera(2.0, 0.1), Level(0.5, 200))    # moving on: released
        assert set(levels._paths) == {(False, None)}
    finally:
        levels.release()
        stream.close()
        lazy.close()


def test_cpu_exact_is_refused_over_a_streamed_scene(tmp_path, gl_renderer):
    from splatgl.errors import SplatglError

    stream, _, lazy = _stream(tmp_path)
    levels = StreamedLevels(gl_renderer, stream, SETTINGS)
    try:
        with pytest.raises(SplatglError, match=r"^--renderer cpu and --memory"):
            levels.draw_cpu(_camera(2.0))
    finally:
        levels.release()
        stream.close()
        lazy.close()


def test_session_reaches_the_exact_frame_when_the_cut_outgrows_the_chunk_cache(tmp_path,
                                                                              gl_renderer):
    """A view's cut whose chunks do not all fit the chunk cache at once (resident_cut thrashed
    and never completed: the 20M flight never reached the exact frame at rest) is gathered in
    the background as a headless frame is: resident ancestors are drawn meanwhile, then the
    frame at rest is exact and is the exact cut's image; the cache stays under its budget."""
    memory = 40 << 10   # about 11 of the scene's 63 chunks
    stream, chunks, lazy = _stream(tmp_path, memory=memory)
    session = streamed_session(gl_renderer, stream, SETTINGS, 10.0)
    try:
        camera = _camera(2.5)
        rows, _ = stream._cut(camera, SETTINGS, stream.lod)
        assert not stream.resident.fits(rows)
        first = session.frame(camera)
        assert first is not None and not session.exact
        assert _until(lambda: (session.frame(camera), session.exact)[1], 20)
        assert stream.complete and session.status == "exact" and session.shown.splats == rows.size
        got = session.levels.read(session.shown)
        want = gl_renderer.render(stream.exact_scene(camera, SETTINGS), camera, SETTINGS)
        assert np.array_equal(got, want)
        assert stream.resident.stats.peak_bytes <= memory
        assert session.frame(camera) is None   # at rest: nothing new, nothing gathered again
    finally:
        session.release()
        stream.close()
        lazy.close()


def test_a_background_gather_is_abandoned_for_another_cut_and_on_close(tmp_path, gl_renderer):
    """While the cut that does not fit is gathered (its loads held back), a moving frame's
    budgeted cut abandons it and draws what is resident; closing the stream stops it."""
    memory = 40 << 10
    stream, chunks, lazy = _stream(tmp_path, memory=memory, gated=True)
    levels = StreamedLevels(gl_renderer, stream, SETTINGS)
    try:
        camera = _camera(2.5)
        levels.draw(camera, EXACT)   # a moving frame: no gather
        assert not levels.complete and stream._job is None
        levels.draw(camera, EXACT)   # the same view again (at rest): gathered
        assert not levels.complete and stream._job is not None
        levels.draw(_camera(2.0, 0.1), Level(1.0, 200))
        assert stream._job is None
        levels.draw(camera, EXACT)
        levels.draw(camera, EXACT)
        thread = stream._thread
        chunks.gate.set()
        stream.close()
        thread.join(5)
        assert not thread.is_alive() and stream._error is None
    finally:
        levels.release()
        stream.close()
        lazy.close()


def test_at_rest_a_cut_that_outgrows_the_cache_is_gathered_with_no_chunk_arriving(tmp_path,
                                                                                    gl_renderer):
    """A moving frame does not gather the cut that does not fit but asks for a redraw, so the
    next frame at rest gathers it even when no chunk arrives in between (its loads held back:
    a full cache whose chunks the cut keeps loads nothing, and the rest waited forever)."""
    stream, chunks, lazy = _stream(tmp_path, memory=40 << 10, gated=True)
    session = streamed_session(gl_renderer, stream, SETTINGS, 10.0)
    try:
        camera = _camera(2.5)
        assert session.frame(camera).level == EXACT and stream._job is None   # moving
        assert session.frame(camera) is not None and stream._job is not None  # at rest
        chunks.gate.set()
        assert _until(lambda: (session.frame(camera), session.exact)[1], 20)
    finally:
        session.release()
        stream.close()
        lazy.close()
