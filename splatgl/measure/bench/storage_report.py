"""The GPU storage comparison of ``splatgl bench`` (group ``storage``): per scene and mode, GPU
bytes per splat (and the ratio to float32), median frame time, and PSNR against the float32
render of the same path and against the NumPy reference (lowest over the error frames; "inf":
identical to float32, as HALF_SH is on SH0 scenes)."""

from __future__ import annotations

from .report import _fmt
from .runner import BenchRow


def storage_table(rows: list[BenchRow]) -> str:
    """A table, one line per scene and storage mode (the default row first); empty when no
    storage rows ran."""
    lines = []
    for scene in dict.fromkeys(r.scene for r in rows):
        sub = [r for r in rows if r.scene == scene]
        modes = [r for r in sub if r.group == "storage"]
        default = next((r for r in sub if r.config == "default"), None)
        if not modes or default is None:
            continue
        # The float32 row: "storage=float32" where the default stores otherwise, else the default.
        f32 = next((r for r in modes if r.config == "storage=float32"), default).gpu_bytes_per_splat
        for r in [default] + modes:
            ratio = f32 / r.gpu_bytes_per_splat if f32 and r.gpu_bytes_per_splat else None
            lines.append(
                f"{scene[:28]:<28} {r.config:<18} {_fmt(r.gpu_bytes_per_splat, '.1f'):>9} "
                f"{_fmt(ratio, '.2f'):>8} {r.frame_ms:>8.1f} {_fmt(r.psnr_float32, '.1f', '-'):>9} "
                f"{_fmt(r.psnr, '.2f'):>8}")
    if not lines:
        return ""
    head = (f"{'GPU storage':<28} {'config':<18} {'B/splat':>9} {'f32/this':>8} {'ms':>8} "
            f"{'PSNR f32':>9} {'PSNR ref':>8}")
    return "\n".join([head] + lines)
