"""``splatgl bench --scale``: argument handling and output of the scale benchmark."""

from __future__ import annotations

import argparse

from ..errors import SplatglError
from .machine import describe, probe_machine
from .scale import SH3_SIZES, SIZES, ScaleOptions, run_scale
from .scale_report import plot, table, write_json


def parse_sizes(text: str | None, default: tuple[int, ...], flag: str) -> tuple[int, ...]:
    """'0.1M,300k,6M' -> (100000, 300000, 6000000); None -> ``default``; 'none' -> ()."""
    if text is None:
        return default
    if text.strip().lower() == "none":
        return ()
    out = []
    for word in text.split(","):
        w = word.strip()
        mult = {"k": 1_000, "m": 1_000_000}.get(w[-1:].lower(), 1)
        try:
            value = float(w[:-1] if mult > 1 else w) * mult
        except ValueError:
            raise SplatglError(f"{flag}: '{w}' is not a size (e.g. 0.1M, 300k, 6M)") from None
        if value < 1:
            raise SplatglError(f"{flag}: sizes must be at least 1 splat, got '{w}'")
        out.append(int(round(value)))
    return tuple(out)


def run_scale_command(args: argparse.Namespace) -> int:
    sizes = parse_sizes(args.sizes, SIZES, "--sizes")
    sh3 = parse_sizes(args.sh3_sizes, SH3_SIZES, "--sh3-sizes")
    resolutions = ((args.width, args.height),) if args.width and args.height else ScaleOptions.resolutions
    frames = args.frames or ScaleOptions.frames
    options = ScaleOptions(sizes=sizes, sh3_sizes=sh3, resolutions=resolutions, frames=frames)
    machine = probe_machine()  # first: a run on the wrong device is seen before it starts
    print(describe(machine), flush=True)
    rows = run_scale(options, log=lambda m: print(m, flush=True))
    if not rows:
        raise SplatglError("scale benchmark: no size could be measured")
    extra = {"cpu": machine["cpu"], "gl_renderer": machine["gl_renderer"], "frames": frames,
             "machine": machine}
    print(f"scale benchmark, median of {frames} frames along an orbit per size and resolution; "
          + describe(machine))
    print(table(rows))
    if args.out is not None:
        args.out.mkdir(parents=True, exist_ok=True)
        write_json(args.out / "scale.json", rows, extra)
        plot(args.out / "scale.png", rows)
        print(f"wrote {args.out / 'scale.json'}, scale.png")
    return 0
