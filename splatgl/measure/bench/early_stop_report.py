"""The early-termination comparison of ``splatgl bench --groups early-stop``: on, off and auto.

Per scene: frame time without early termination (off), always batched (on) and with the
default's per-view choice (auto), each on the same path in one run, with the speed-ups over
off, the share of auto's frames it batched and what it decided on (its estimate of the
fragments a plain draw rasterises, per drawn quad and per image pixel); fragments shaded (quad.frag invocations, from
the untimed counting pass) off and on, fragments rasterised with it on (those its depth test
rejects before shading included), splats the occlusion cull dropped, the NumPy reference's
blended fragments (the floor of a renderer that stops exactly) and on's ratio to it, and PSNR
against the reference off and on.
"""

from __future__ import annotations

from ...scene.settings import EarlyStop
from .report import _fmt
from .runner import BenchRow

_MODES = [m.value for m in EarlyStop]


def _by_mode(rows: list[BenchRow]) -> dict[str, BenchRow]:
    """One scene's rows keyed by early-termination mode: the ``early-stop=X`` rows, and the
    default row for the mode none of them names."""
    found = {r.config.split("=", 1)[1]: r for r in rows
             if r.group == "early-stop" and r.config.split("=", 1)[-1] in _MODES}
    default = next((r for r in rows if r.config == "default"), None)
    missing = [m for m in _MODES if m not in found]
    if default is not None and len(missing) == 1:
        found[missing[0]] = default
    return found


def _ratio(a: float | None, b: float | None) -> float | None:
    return a / b if a is not None and b else None


def early_stop_table(rows: list[BenchRow], pixels: int | None = None) -> str:
    """A table, one line per scene; empty when no early-stop rows ran.  ``pixels``: the image's
    pixel count (for auto's fragments per pixel; '-' without)."""
    lines = []
    for scene in dict.fromkeys(r.scene for r in rows):
        modes = _by_mode([r for r in rows if r.scene == scene])
        on, off, auto = modes.get("on"), modes.get("off"), modes.get("auto")
        if on is None or off is None:
            continue
        ref = on.reference_fragments
        ratio = _ratio(on.fragments_shaded, ref)
        estimate = auto.fragments_estimate if auto else None
        per_quad = _ratio(estimate, auto.drawn if auto else None)
        per_pixel = _ratio(estimate, pixels)
        lines.append(
            f"{scene[:28]:<28} {on.splats:>9} {off.frame_ms:>8.1f} {on.frame_ms:>8.1f} "
            f"{off.frame_ms / on.frame_ms:>6.2f}x "
            f"{_fmt(auto.frame_ms if auto else None, '.1f'):>8} "
            f"{_fmt(_ratio(off.frame_ms, auto.frame_ms if auto else None), '.2f'):>6}x "
            f"{_fmt(auto.batched_share if auto else None, '.0%'):>7} "
            f"{_fmt(per_quad, '.0f'):>9} {_fmt(per_pixel, '.1f'):>8} "
            f"{_fmt(off.fragments_shaded, ',d'):>13} "
            f"{_fmt(on.fragments_shaded, ',d'):>13} {_fmt(on.fragments_rasterised, ',d'):>13} "
            f"{_fmt(on.occlusion_culled, ',d'):>10} "
            f"{_fmt(ref, ',d'):>13} {_fmt(ratio, '.2f'):>7} {_fmt(off.psnr, '.2f'):>8} "
            f"{_fmt(on.psnr, '.2f'):>7}")
    if not lines:
        return ""
    head = (f"{'early termination':<28} {'splats':>9} {'off ms':>8} {'on ms':>8} {'on':>7} "
            f"{'auto ms':>8} {'auto':>7} {'batched':>7} {'frag/quad':>9} {'frag/px':>8} "
            f"{'shaded off':>13} {'shaded on':>13} {'rast. on':>13} {'occl-cull':>10} "
            f"{'ref frags':>13} {'on/ref':>7} {'PSNR off':>8} {'PSNR on':>7}")
    return "\n".join([head] + lines)
