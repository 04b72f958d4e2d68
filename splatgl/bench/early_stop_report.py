"""The early-termination comparison of ``splatgl bench --groups early-stop``: on against off.

Per scene: frame time with and without early termination (the same path, one run), fragments
shaded (quad.frag invocations, from the untimed counting pass), fragments rasterised with it on
(those its depth test rejects before shading included), splats the occlusion cull dropped, the NumPy reference's blended fragments (the floor of a renderer that stops exactly)
and the ratio to it, and PSNR against the reference.
"""

from __future__ import annotations

from .report import _fmt
from .runner import BenchRow


def _pair(rows: list[BenchRow]) -> tuple[BenchRow, BenchRow] | None:
    """(on, off) rows of one scene: the default row and the early-stop row, by setting."""
    default = next((r for r in rows if r.config == "default"), None)
    toggled = next((r for r in rows if r.group == "early-stop"), None)
    if default is None or toggled is None:
        return None
    return (toggled, default) if toggled.config == "early-stop=on" else (default, toggled)


def early_stop_table(rows: list[BenchRow]) -> str:
    """A table, one line per scene; empty when no early-stop rows ran."""
    lines = []
    for scene in dict.fromkeys(r.scene for r in rows):
        pair = _pair([r for r in rows if r.scene == scene])
        if pair is None:
            continue
        on, off = pair
        ref = on.reference_fragments
        ratio = on.fragments_shaded / ref if ref and on.fragments_shaded is not None else None
        lines.append(
            f"{scene[:28]:<28} {on.splats:>9} {off.frame_ms:>8.1f} {on.frame_ms:>8.1f} "
            f"{off.frame_ms / on.frame_ms:>7.2f}x {_fmt(off.fragments_shaded, ',d'):>13} "
            f"{_fmt(on.fragments_shaded, ',d'):>13} {_fmt(on.fragments_rasterised, ',d'):>13} "
            f"{_fmt(on.occlusion_culled, ',d'):>10} "
            f"{_fmt(ref, ',d'):>13} {_fmt(ratio, '.2f'):>7} {_fmt(off.psnr, '.2f'):>7} "
            f"{_fmt(on.psnr, '.2f'):>7}")
    if not lines:
        return ""
    head = (f"{'early termination':<28} {'splats':>9} {'off ms':>8} {'on ms':>8} {'speedup':>8} "
            f"{'shaded off':>13} {'shaded on':>13} {'rast. on':>13} {'occl-cull':>10} {'ref frags':>13} "
            f"{'on/ref':>7} {'PSNR off':>7} {'PSNR on':>7}")
    return "\n".join([head] + lines)
