"""The command lines of the benchmark tools run as modules: ``python -m
splatgl.commands._bench_tools gpu-probe`` (the first step of ``benchmarks/gpu_check.sh``) and ``python -m
splatgl.commands._bench_tools scale-report`` (merging the scale.json of separate runs)."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from ..errors import SplatglError


def gpu_probe_main(argv: list[str] | None = None) -> int:
    """``python -m splatgl.commands._bench_tools gpu-probe``: :func:`splatgl.measure.bench.gpu_probe.probe`, printed and
    written to ``--out``; exit 1 on a software renderer unless ``--allow-software``, 2 on an
    error (one line)."""
    from ..measure.bench import gpu_probe
    from ..measure.bench.machine import describe
    from ..writing.atomic import atomic_write_text

    p = argparse.ArgumentParser(prog="python -m splatgl.commands._bench_tools gpu-probe", description=gpu_probe.__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--out", type=Path, default=None, help="write the JSON there (machine.json)")
    p.add_argument("--commit", default=None, help="the source revision, recorded as given")
    p.add_argument("--allow-software", action="store_true",
                   help="do not fail on a software renderer (trying the check without a GPU)")
    args = p.parse_args(argv)
    try:
        doc = gpu_probe.probe(args.commit)
        if args.out is not None:
            atomic_write_text(args.out, json.dumps(doc, indent=1) + "\n")
    except SplatglError as exc:
        print(f"gpu_probe: error: {exc}", file=sys.stderr)
        return 2
    gl = doc["gl"]
    print(describe(doc["machine"]))
    print(f"GL renderer: {gl['renderer']}")
    print(f"GL vendor: {gl['vendor']}; GL version: {gl['version']}; "
          f"{doc['egl_device_list']}")
    for reason in gl["egl_skipped"]:
        print(f"EGL device skipped: {reason}")
    if gl["software"]:
        what = "allowed (--allow-software)" if args.allow_software else "error"
        print(f"gpu_probe: {what}: GL renderer '{gl['renderer']}' is a software rasteriser, "
              f"not the GPU; {gpu_probe.SOFTWARE_HINT}", file=sys.stderr)
        return 0 if args.allow_software else 1
    return 0


def scale_report_main(argv: list[str] | None = None) -> int:
    """Merge scale.json files of separate runs (e.g. one per size) into one table and plot."""
    from ..measure.bench.scale_report import merge_reports, plot, table, write_json

    p = argparse.ArgumentParser(prog="python -m splatgl.commands._bench_tools scale-report",
                                description=scale_report_main.__doc__)
    p.add_argument("inputs", nargs="+", type=Path, help="scale.json files")
    p.add_argument("--out", type=Path, required=True, help="folder for the merged scale.json, scale.png")
    args = p.parse_args(argv)
    rows, extra = merge_reports(args.inputs)
    print(table(rows))
    args.out.mkdir(parents=True, exist_ok=True)
    write_json(args.out / "scale.json", rows, extra)
    plot(args.out / "scale.png", rows)
    print(f"wrote {args.out / 'scale.json'}, scale.png")
    return 0


if __name__ == "__main__":  # python -m splatgl.commands._bench_tools gpu-probe|scale-report ...
    tools = {"gpu-probe": gpu_probe_main, "scale-report": scale_report_main}
    if len(sys.argv) < 2 or sys.argv[1] not in tools:
        print(f"usage: python -m splatgl.commands._bench_tools {{{','.join(tools)}}} ...", file=sys.stderr)
        raise SystemExit(2)
    raise SystemExit(tools[sys.argv[1]](sys.argv[2:]))
