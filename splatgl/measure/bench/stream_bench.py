"""``splatgl bench SCENE.lod.ply --memory SIZE`` (issue 41 item 3): frames of a level of detail
streamed under a memory budget along an orbit (:class:`splatgl.lod.stream_frames.StreamFrames`,
every frame exact): the first frame's time (a cold start: the chunks it needs are read), the
median of the rest, what stayed resident, chunks loaded and evicted, bytes read, and the
process's peak resident memory."""

from __future__ import annotations

import resource
import sys
import time

import numpy as np

from ...lod.budget import format_size
from ...lod.selection import LodSettings
from ...lod.stream_frames import StreamFrames
from ...lod.stream_levels import ChunkedFrames, is_chunked
from ...renderers import auto
from ...scene.settings import RendererKind, RenderSettings
from ...paths import orbit


def peak_rss() -> int:
    """Bytes: this process's peak resident memory so far."""
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return int(peak if sys.platform == "darwin" else peak * 1024)


def run_stream(path, memory: int, width: int, height: int, frames: int,
               settings: RenderSettings = RenderSettings(), lod: LodSettings = LodSettings(),
               level: int | None = None, kind: RendererKind | None = None) -> dict:
    """The figures of ``frames`` orbit frames of the ``.lod.ply`` (or Streamed SOG or LCC: each
    chunk's level by screen error, or ``level``) at ``path`` under ``memory`` bytes (a dict,
    seconds and bytes; ``bytes_read`` None where the reader does not count them), drawn by
    renderer ``kind`` (None: ``--renderer auto``'s choice, :func:`splatgl.renderers.auto.choose`,
    said once on stderr where only the CPU renderer's kernels were missing)."""
    chunked = is_chunked(path)
    if kind is None:
        choice = auto.choose(settings=settings)
        auto.compiling_notice(choice, background=False)
        kind, why = choice.kind, choice.text()
    else:
        why = f"renderer {RendererKind(kind).value}"
    t0 = time.perf_counter()
    with (ChunkedFrames(path, settings, lod, memory, level, kind) if chunked
          else StreamFrames(path, settings, lod, memory, kind=kind)) as stream:
        opened = time.perf_counter() - t0
        times, nodes = [], []
        for camera in orbit(stream.framing, frames, width, height):
            t = time.perf_counter()
            stream.render_view(camera)
            times.append(time.perf_counter() - t)
            nodes.append(stream.last_cut_nodes)
        stats = stream.resident.stats
        read = None if chunked else stream.lazy.bytes_read
        capped = getattr(stream, "capped", None)   # the memory bound's coarser cut, said once
        plan = getattr(stream, "plan", None)
        cap = None if plan is None else plan.cap
    return {"scene": str(path), "memory": memory, "width": width, "height": height,
            "frames": frames, "open_s": opened, "first_frame_s": times[0],
            "median_frame_s": float(np.median(times[1:] if len(times) > 1 else times)),
            "cut_nodes_median": int(np.median(nodes)), "resident_bytes": stats.resident_bytes,
            "resident_peak_bytes": stats.peak_bytes, "chunks_loaded": stats.loaded,
            "chunks_evicted": stats.evicted, "bytes_read": read, "peak_rss_bytes": peak_rss(),
            "frame_cap": cap, "capped": capped, "renderer": RendererKind(kind).value,
            "renderer_choice": why}


def describe(r: dict) -> str:
    """The figures as lines for the terminal."""
    return (f"{r['scene']} streamed under {format_size(r['memory'])}: {r['frames']} frames at "
            f"{r['width']}x{r['height']} along an orbit ({r.get('renderer_choice', 'quad')})\n"
            f"open {r['open_s'] * 1e3:.1f} ms, first frame {r['first_frame_s'] * 1e3:.1f} ms, "
            f"median frame {r['median_frame_s'] * 1e3:.1f} ms ({r['cut_nodes_median']:,} nodes)\n"
            f"resident {format_size(r['resident_bytes'])} (peak "
            f"{format_size(r['resident_peak_bytes'])}), chunks {r['chunks_loaded']} loaded, "
            f"{r['chunks_evicted']} evicted"
            f"{'' if r['bytes_read'] is None else ', ' + format_size(r['bytes_read']) + ' read'}; process peak "
            f"RSS {format_size(r['peak_rss_bytes'])}"
            f"{'' if not r.get('capped') else chr(10) + r['capped']}")
