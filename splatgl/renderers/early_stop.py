"""Early termination for the quad path: stop shading pixels that are already opaque.

``coverage`` (shaders/coverage.comp) first estimates the fragments a plain draw would
rasterise.  With ``--early-stop on`` the sorted splats are then drawn in batches
(:func:`batch_bounds`, COARSE_SCHEDULE or, for views of very large quads, FINE_SCHEDULE); with
``auto`` (the default) only views of large quads over an overdrawn image are
(``constants.EARLY_STOP_MIN_QUAD_FRAGMENTS``, ``EARLY_STOP_MIN_OVERDRAW``), and the other views
get one plain draw.  Between batches:

1. ``mark`` (shaders/stop_mark.*): a full-screen pass writes depth 0 wherever the accumulated
   transmittance ``T = 1 - A`` is below ``T_MIN`` (the reference's stop threshold); splat quads
   sit at depth 0.5 and are drawn with ``depth < stored`` and ``early_fragment_tests``, so their
   fragments on marked pixels are rejected before shading.
2. ``stop_tiles`` (shaders/stop_tiles.comp): one word per 16 x 16 tile, a bit per 4 x 4 block
   whose pixels are all marked.
3. ``occlusion_cull`` (shaders/occlusion_cull.comp): the next batch's splats whose quad
   rectangle lies only on stopped blocks are dropped, the survivors compacted in order, one
   draw command per SEGMENT slots, and the batch is drawn with one multi-draw-indirect.

Accuracy (DESIGN.md section 2 and docs/early-stop.md).  A pixel is marked only after a batch
ends with ``T < T_MIN``.  The reference adds splat k while ``T_k (1 - alpha_k) >= T_MIN``, so
while it still adds splats the running T is at least T_MIN and the pixel is not marked: the
quad path receives every splat the reference blends, plus, on pixels the reference stopped,
the splats up to the end of the batch where T fell below T_MIN.  Their total weight is
``T_stop - T_end <= T_stop < T_MIN / (1 - ALPHA_MAX) = 0.01`` (``T_stop``: the reference's T
when it stopped), a prefix of what the quad path added before (no stop at all), so each pixel's
error against the reference is at most ``0.01 max|c - bg|`` and never more weight than without
the stop.  The occlusion cull drops only splats whose every fragment the depth test would
reject, so it changes no pixel.  On 8- and 16-bit targets ``1 - A < 1e-4`` holds only
where ``A`` is stored as exactly 1, where blending adds nothing anyway: the image is unchanged.

NumPy twins: :mod:`splatgl.splatmath.early_stop` (``stop_mask``, ``stop_tiles``
(``stop_blocks``), ``occlusion_cull``, ``coverage``).
"""

from __future__ import annotations

import math
from typing import Callable

from ..constants import STOP_BLOCK_SIZE, TILE_SIZE
from ..gl.bindings import OCCLUSION_GROUP, OCCLUSION_PER_INVOCATION

#: Slots per draw command of the occlusion cull (one work group of occlusion_cull.comp).
SEGMENT = OCCLUSION_GROUP * OCCLUSION_PER_INVOCATION
#: Bytes per draw command: DrawArraysIndirectCommand (count, instanceCount, first, baseInstance)
#: and one padding uint, since moderngl's render_indirect uses a 20-byte stride for arrays too.
COMMAND_BYTES = 20
#: A tile's stop word when all its blocks are stopped (16 blocks, shaders/stop_tiles.comp).
TILE_STOPPED = (1 << (TILE_SIZE // STOP_BLOCK_SIZE) ** 2) - 1
#: The fewest invocations shaders/coverage.comp runs with (each sums every stride-th slot;
#: llvmpipe ends an invocation's loops after 65535 iterations, so the invocations grow with the
#: count beyond COVERAGE_SLOTS_PER_INVOCATION slots each).
COVERAGE_MIN_INVOCATIONS = 1024
COVERAGE_SLOTS_PER_INVOCATION = 16384

#: Batch schedules (chosen by measurement, docs/early-stop.md), (first share, growth): the first
#: batch holds that share of the sorted splats (at least MIN_BATCH), each next one GROWTH times
#: the previous.  Each batch boundary costs llvmpipe the overlap of its single-threaded per-quad
#: work with rasterisation and saves shading in proportion to fragments, so views of large
#: quads (``constants.EARLY_STOP_FINE_QUAD_FRAGMENTS`` per quad and more) take the fine schedule
#: (about 8 batches), the others the coarse one (3 batches: 1/8, 5/16, the rest).
COARSE_SCHEDULE = (1.0 / 8.0, 2.5)
FINE_SCHEDULE = (1.0 / 64.0, 1.6)
FIRST_BATCH_FRACTION, GROWTH = COARSE_SCHEDULE
MIN_BATCH = 512
#: No batch is longer than this (a long draw stays interruptible between batches; with early
#: termination off, the draw is split into batches of this size only).
MAX_BATCH = 1 << 20

#: ``on_batch(done, total)``: called after each batch with the sorted splats drawn so far; it may
#: raise (KeyboardInterrupt) to abandon the frame.
BatchHook = Callable[[int, int], None]


def batch_bounds(count: int, first_fraction: float = FIRST_BATCH_FRACTION, growth: float = GROWTH,
                 min_batch: int = MIN_BATCH, max_batch: int = MAX_BATCH) -> list[int]:
    """Batch boundaries ``[0, e_0, e_1, ..., count]`` of a geometric schedule.

    The first batch has ``max(min_batch, ceil(count * first_fraction))`` splats, each next one
    ``growth`` times as many, none more than ``max_batch``.  ``growth`` <= 1 gives equal batches.
    """
    bounds = [0]
    size = float(max(min_batch, math.ceil(count * first_fraction)))
    while bounds[-1] < count:
        step = int(min(max_batch, max(1, size)))
        bounds.append(min(count, bounds[-1] + step))
        size *= max(growth, 1.0)
    return bounds


def plain_bounds(count: int, max_batch: int = MAX_BATCH) -> list[int]:
    """Boundaries of the draw without early termination: batches of ``max_batch``."""
    return list(range(0, count, max_batch)) + [count] if count else [0]

