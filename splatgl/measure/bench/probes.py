"""Benchmark probes on the quad path: fragment counters and a GPU timer around its draw.

They reach the draw only through the renderer's two hooks (:attr:`QuadRenderer.frame_extra`,
extra shader switches, and :attr:`QuadRenderer.around_draw`), so the renderer carries no
benchmark code of its own.
"""

from __future__ import annotations

import numpy as np

from ...cameras.view import View
from ...gl.bindings import BINDING_FRAGMENT_COUNTS
from ...renderers.quad import QuadRenderer


def count_fragments(quad: QuadRenderer, view: View, rasterised: bool = False) -> tuple[int, int]:
    """Draw once with counting shaders: (fragments shaded, fragments with alpha >= 1/255).

    Their ratio is the quad extent's fragment efficiency (the benchmark reports it).  With
    ``rasterised`` the first figure counts every fragment rasterised: with early
    termination the depth test then runs after the counter, so the fragments it rejects
    are counted too (without it, rasterised and shaded are the same).
    Atomic counters slow the draw, so this is a separate, untimed pass.
    """
    counts = quad.ctx.buffer(np.zeros(2, np.uint32).tobytes())
    counts.bind_to_storage_buffer(BINDING_FRAGMENT_COUNTS)
    quad.frame_extra = {"COUNT_FRAGMENTS": 1, **({"COUNT_RASTERISED": 1} if rasterised else {})}
    try:
        quad.draw(view, quad.target(view))
    finally:
        quad.frame_extra = {}
    shaded, kept = np.frombuffer(counts.read(), np.uint32)
    counts.release()
    return int(shaded), int(kept)


def _valid_elapsed(ns: int) -> int | None:
    """A timer query's nanoseconds, or None where the driver returns no real value (llvmpipe
    answers 2^32 - 1)."""
    return int(ns) if 0 < ns < 0xFFFFFFFF else None


class GpuTimer:
    """Times the quad path's draw with a GL timer query while attached (:meth:`attach`);
    :attr:`last_ns` holds the last draw's nanoseconds, or None where the driver has no timer."""

    def __init__(self, quad: QuadRenderer):
        self.quad = quad
        self.query = quad.ctx.query(time=True)
        self.last_ns: int | None = None

    def around(self, draw) -> None:
        with self.query:
            draw()
        self.quad.ctx.finish()
        self.last_ns = _valid_elapsed(self.query.elapsed)

    def attach(self) -> "GpuTimer":
        self.quad.around_draw = self.around
        return self

    def detach(self) -> None:
        if self.quad.around_draw == self.around:
            self.quad.around_draw = None

    def release(self) -> None:
        self.detach()
