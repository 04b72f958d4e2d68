"""A streamed frame's cut under ``--memory`` (issue 41 item 3): the whole process stays within
the one budget, not only the chunk cache.

:func:`plan_for` splits the budget (:func:`splatgl.lod.budget.stream_plan`): what the process
holds already and the draw's reserve off first, then the chunk cache's share, the rest the
frame's; the frame's bytes over :func:`~splatgl.lod.budget.frame_bytes_per_splat` give the most
splats a frame draws (:attr:`~splatgl.lod.budget.StreamPlan.cap`).  :func:`choose_cut` chooses
the cut by screen-space error under ``min(--lod-budget, cap)``: the threshold cut (or the
leaves it switches to) where it fits, else the finest cut within the cap
(:func:`splatgl.lod.cut_budget.select_cut_budget`), which is exactly the cut the in-memory level
of detail draws with that budget.  Every trial cut is abandoned once it passes a few times the cap
(:class:`splatgl.lod.cut.CutTooLarge`), so choosing never reads the spheres of more than that.

    plan = plan_for(lazy, memory, GpuStorage.FLOAT32)    # once, after the GL context exists
    choice = choose_cut(lazy, camera, lod, plan.cap)     # rows, weights, capped (a line or None)
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..cameras.camera import Camera
from ..gl.storage import gpu_bytes_per_splat
from ..order import kernels
from ..scene.settings import GpuStorage
from .budget import StreamPlan, frame_bytes_per_splat, stream_plan
from .cut import CutTooLarge, select_cut_weights
from .cut_budget import select_cut_budget
from .lazy import LazyLod
from .selection import LodSettings, threshold_cut
from .stream import LOADERS, PINNED_LEVELS

#: Trees of more nodes than this wait for the compiled cut (numba's load, about a second from
#: its on-disk cache) for their first view rather than search with NumPy: there a budget's
#: search gathers and tests millions of spheres per trial in float64 temporaries (about 8 s and
#: 700 MB at 100M splats); smaller ones take it once loaded.  The same cut either way.
COMPILED_CUT_NODES = 1 << 22
#: The threshold of the cut that stands for "the leaves" (every leaf in view).
LEAVES_PX = 1e-30
#: Sphere pages a streamed frame keeps between views: this many times 16 bytes a splat of the
#: cap (beyond it they are dropped after the cut and read again as needed).
SPHERE_PAGES_PER_SPLAT = 2


@dataclass(frozen=True)
class CutChoice:
    """A streamed view's cut: node ``rows`` (ascending), ``weights`` (None: all 1), and
    ``capped``: one line saying how the memory bound made it coarser than asked, or None."""

    rows: np.ndarray
    weights: np.ndarray | None
    capped: str | None = None


def tree_cache_need(chunks, offsets, threads: int = LOADERS) -> int:
    """Bytes a :class:`~splatgl.lod.stream.ResidentSet` over a tree's ``chunks`` needs at
    least: its pinned top levels' chunks and ``threads`` of the largest in flight (what a
    memory plan's cache share must hold, :func:`splatgl.lod.budget.stream_plan`)."""
    top = max(0, len(offsets) - 1 - PINNED_LEVELS)
    pinned = range(int(offsets[top]) // chunks.rows, chunks.count)
    largest = max((chunks.estimate(c) for c in range(chunks.count)), default=0)
    return sum(chunks.estimate(c) for c in pinned) + largest * max(1, threads)


def per_splat(lazy: LazyLod, storage: GpuStorage | str = GpuStorage.FLOAT32) -> int:
    """Bytes of the whole process per splat a frame of ``lazy`` draws (its SH degree and the
    renderer's ``storage``)."""
    node = lazy.nodes(np.zeros(1, np.int64))
    return frame_bytes_per_splat(node.sh.shape[1], gpu_bytes_per_splat(storage, node.sh_degree))


#: A viewer holds the scene it draws and its upload while the next cut is gathered, weighted
#: (float64 temporaries) and uploaded: about 2.3 times a headless frame's bytes a splat
#: (measured: a 5M scene's flight peaked at 3.6 GB under --memory 2G with a headless frame's
#: cap of 4.26M splats), so its cap is a third of a headless frame's.
VIEWER_FRAMES = 3


def plan_for(lazy: LazyLod, memory: int, storage: GpuStorage | str = GpuStorage.FLOAT32,
             cache_need: int = 0, held: int | None = None, frames: int = 1) -> StreamPlan:
    """The split of ``memory`` for streamed frames of ``lazy`` (see the module doc): ``held``
    measured now when None (call it once the GL context exists); ``frames``: how many frames'
    nodes the process holds at once (VIEWER_FRAMES for the viewer's)."""
    return stream_plan(memory, frames * per_splat(lazy, storage), cache_need, held)


def cut_kernels(lazy: LazyLod):
    """The compiled kernels for a streamed view's cut (:func:`splatgl.order.kernels.for_view`),
    waited for on a tree of more than COMPILED_CUT_NODES nodes (unless the kernel policy says
    otherwise), else the ones already loaded, or None (NumPy's cut)."""
    if int(lazy.offsets[-1]) > COMPILED_CUT_NODES and kernels.policy() == "auto":
        return kernels.for_view(kernels.FROM_VIEW, True)
    return kernels.for_view(1)   # whatever is loaded already; a small tree's cut asks for none


def _capped(lazy: LazyLod, camera: Camera, lod: LodSettings, cap: int, asked: str, kern
            ) -> CutChoice:
    rows, weights, t = select_cut_budget(lazy.cut_data, camera, cap, lod.threshold_px, lod.band,
                                         kern)
    if not np.isfinite(t) or t > lod.threshold_px:
        note = (f"the memory bound made the cut coarser than {asked}: {rows.size:,} nodes at "
                f"{t:.3g} px (the frame holds at most {cap:,} splats)")
        return CutChoice(rows, weights, note)
    return CutChoice(rows, weights)


def choose_cut(lazy: LazyLod, camera: Camera, lod: LodSettings, cap: int | None = None
               ) -> CutChoice:
    """The cut a streamed frame draws for ``camera`` (no warm start): without ``cap`` the one
    :class:`~splatgl.lod.source.LodOrder` draws (the leaves where the threshold cut switches
    to them); with it, that cut where it has at most ``cap`` nodes, else the finest cut of at
    most ``cap`` (``--lod-budget``'s cut with ``min(budget, cap)``), ``capped`` saying so.
    Compiled where :func:`cut_kernels` gives the kernels (the same cut)."""
    data = lazy.cut_data
    kern = cut_kernels(lazy)
    if lod.budget is not None:
        if cap is not None and cap < lod.budget:
            return _capped(lazy, camera, lod, cap, f"--lod-budget {lod.budget:,} asked", kern)
        rows, weights, _ = select_cut_budget(data, camera, lod.budget, lod.threshold_px, lod.band,
                                             kern)
        return CutChoice(rows, weights)
    asked = f"--lod-threshold {lod.threshold_px:g} px asked"
    try:
        rows, weights, _ = threshold_cut(lazy, data, camera, lod, kern, max_nodes=cap)
        if rows is None:   # the leaves, every one in view (the in-memory path culls them by chunks)
            return CutChoice(select_cut_weights(data, camera, LEAVES_PX, 1.0, kern=kern,
                                                max_nodes=cap)[0], None)
    except CutTooLarge:
        return _capped(lazy, camera, lod, cap, asked, kern)
    return CutChoice(rows, weights)
