"""Peak memory of ``splatgl edit``, ``convert`` and ``info --stats`` in memory and streamed
within ``--memory`` (issue 41 item 5): PLY, .splat and compressed PLY outputs, floaters and
decimation per chunk.

    python benchmarks/stream_memory.py [--size 3M] [--sh 3] [--memory 300M] [--out FILE.json]
                                       [--only TEXT ...]

The scene is the scale benchmark's real-data scene (:func:`splatgl.measure.bench.scale.scene_file`,
built from the shared scenes on first use and cached in the temporary folder, never in the
repository).  Each case runs in a fresh child process (its peak resident memory, VmHWM, is its
own), once with the default budget (half the RAM: the scene loads whole) and once with
``--memory``; the two output files must be identical byte for byte (but the decimation's,
chunked: the same count, other merges).  Seconds are printed but
are not benchmark figures where other work shares the machine.
"""

from __future__ import annotations

import argparse
import filecmp
import json
import sys
import tempfile
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from benchmarks.edit_memory import run_child  # noqa: E402
from splatgl.measure.bench.scale import parse_sizes, scene_file  # noqa: E402


def cases(scene: Path, tmp: str) -> list[tuple[str, list[str], str | None]]:
    """(case, argv with {out} for the output, output name or None)."""
    return [
        ("edit: crop, filter, sh-degree", ["edit", str(scene), "-o", "{out}", "--crop-box",
                                           "-inf,-inf,-inf,inf,inf,inf", "--remove",
                                           "opacity < 0.1", "--sh-degree", "2"], "edit.ply"),
        ("convert --sh-degree 1", ["convert", str(scene), "{out}", "--sh-degree", "1"],
         "convert.ply"),
        ("info --stats", ["info", str(scene), "--stats", "--json", "{out}"], None),
        ("convert to .splat", ["convert", str(scene), "{out}"], "convert.splat"),
        ("convert to .compressed.ply", ["convert", str(scene), "{out}"],
         "convert.compressed.ply"),
        ("edit --remove-floaters", ["edit", str(scene), "-o", "{out}", "--remove-floaters"],
         "floaters.ply"),
        # per chunk: the count is the in-memory one, the file differs (docs/editing.md)
        ("edit --decimate 50%", ["edit", str(scene), "-o", "{out}", "--decimate", "50%"],
         "decimate.ply"),
    ]


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--size", default="3M", help="scene size (e.g. 3M, 300k)")
    p.add_argument("--sh", type=int, default=3, help="SH degree of the scene (default 3)")
    p.add_argument("--memory", default="300M", help="the streamed runs' --memory")
    p.add_argument("--out", type=Path, default=None, help="write the rows as JSON here")
    p.add_argument("--only", action="append", default=[],
                   help="run the cases whose name holds this text (repeatable; default all)")
    args = p.parse_args(argv)
    n = parse_sizes(args.size, (), "--size")[0]
    scene = scene_file(n, args.sh)
    print(f"scene {scene.name}: {scene.stat().st_size / 1e6:.0f} MB file", flush=True)
    rows = []
    with tempfile.TemporaryDirectory(dir=scene.parent) as tmp:
        for name, cmd, out in cases(scene, tmp):
            if args.only and not any(text in name for text in args.only):
                continue
            pair = {}
            for how, extra in (("memory", []), ("streamed", ["--memory", args.memory])):
                target = f"{tmp}/{how}-{out or 'info.json'}"
                row = run_child([c.replace("{out}", target) for c in cmd] + extra)
                pair[how] = row
                rows.append({"case": name, "how": how, **row})
                print(f"{name:<30} {how:<9} peak {row['peak_mb']:7.0f} MB  "
                      f"({row['seconds']:.0f} s, exit {row['code']})", flush=True)
            if out is not None:
                same = filecmp.cmp(f"{tmp}/memory-{out}", f"{tmp}/streamed-{out}", shallow=False)
                rows[-1]["identical"] = same
                print(f"{'':<30} outputs identical: {same}", flush=True)
    if args.out:
        args.out.write_text(json.dumps({"scene": scene.name, "splats": n, "memory": args.memory,
                                        "rows": rows}, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
