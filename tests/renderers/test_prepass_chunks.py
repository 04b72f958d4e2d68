"""Long quad-path frames in chunks, polled like the draw's batches, so input can abandon a
million-splat frame within a chunk (issue 27's latency): the compute pre-pass in chunks, and an
early-termination batch drawn ``max_batch`` slots at a time.  Each gives the same image as one
dispatch or draw (same primitives, same order), calls the hook between chunks, and a frame
abandoned there leaves the renderer as it was."""

from __future__ import annotations

import numpy as np
import pytest

from helpers import random_scene, view_for
from splatgl.api import default_camera
from splatgl.gl.bindings import PREPASS_GROUP
from splatgl.scene.settings import EarlyStop, RenderSettings
from splatgl.renderers.early_stop import SEGMENT


class Stop(Exception):
    pass


def test_chunked_prepass_gives_the_same_image_and_polls(gl_renderer):
    scene = random_scene(1000, seed=11, degree=1)
    quad = gl_renderer.renderer_for(scene, RenderSettings(early_stop=False))
    assert quad.uses_prepass
    view = view_for(quad, default_camera(scene, 160, 120))
    whole = quad.render(view).rgba
    calls = []
    chunk = 2 * PREPASS_GROUP   # chunks are whole work groups
    quad.batches.max_batch = chunk
    try:
        chunked = quad.render(view, on_batch=lambda done, total: calls.append(done)).rgba
    finally:
        quad.batches.max_batch = 1 << 20
    visible = quad.last_times.drawn
    polls = -(-visible // chunk) - 1     # between the pre-pass's chunks (done 0) ...
    assert polls >= 2
    assert calls[:polls] == [0] * polls
    assert calls[polls:] == list(range(chunk, visible, chunk)) + [visible]   # ... then batches
    np.testing.assert_array_equal(chunked, whole)


def test_a_hook_raising_in_the_prepass_abandons_the_frame(gl_renderer):
    scene = random_scene(1000, seed=12)
    quad = gl_renderer.renderer_for(scene, RenderSettings(early_stop=False))
    view = view_for(quad, default_camera(scene, 160, 120))
    want = quad.render(view).rgba
    quad.batches.max_batch = 64

    def stop(done, total):
        raise Stop

    try:
        with pytest.raises(Stop):
            quad.render(view, on_batch=stop)
    finally:
        quad.batches.max_batch = 1 << 20
    np.testing.assert_array_equal(quad.render(view).rgba, want)


def test_early_termination_batches_draw_in_chunks_with_the_same_image(gl_renderer):
    scene = random_scene(6000, seed=13)
    quad = gl_renderer.renderer_for(scene, RenderSettings(early_stop=EarlyStop.ON))
    view = view_for(quad, default_camera(scene, 160, 120))
    whole = quad.render(view).rgba
    assert quad.last_times.batched
    batches = quad.last_times.batches
    calls = []
    quad.batches.max_batch = SEGMENT
    try:
        chunked = quad.render(view, on_batch=lambda done, total: calls.append(done)).rgba
    finally:
        quad.batches.max_batch = 1 << 20
    assert quad.last_times.batches == batches      # the same early-termination batches ...
    drawn = [c for c in calls if c > 0]            # (the pre-pass's polls report 0)
    assert len(drawn) > batches                    # ... polled within them too
    assert calls == sorted(calls)
    np.testing.assert_array_equal(chunked, whole)
