#!/usr/bin/env python3
"""Generate interoperability test files with splat-transform (PlayCanvas) from the shared scenes.

    python tests/data/splat_transform_files.py [--out DIR] [--scenes DIR]

Writes, for each source scene below, ``<stem>.sog``, ``<stem>.spz`` (SPZ version 3),
``<stem>.glb`` and ``<stem>.compressed.ply`` into ``tests/data/splat-transform/`` (git-ignored:
regenerated, never committed).  splat-transform is looked up as ``.npm-tools/node_modules/.bin/
splat-transform`` (install it with ``npm install --prefix .npm-tools @playcanvas/splat-transform``)
or on PATH.  tests/test_interop_splat_transform.py calls :func:`generate` itself when the files
are missing and the tool is present, and skips with the reason otherwise.
"""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
DEFAULT_OUT = REPO / "tests" / "data" / "splat-transform"
#: Source scenes (relative to the shared scenes folder): an SH-0 PLY and an SH-3 compressed PLY.
SOURCES = ("ply/donut_sh0.ply", "fixtures/test64_sh3.compressed.ply")
#: Output suffixes and the extra splat-transform arguments for each (SOG: k-means on the CPU,
#: as no GPU adapter need exist).
OUTPUTS = ((".sog", ["-g", "cpu"]), (".spz", ["--spz-version", "3"]), (".glb", []), (".compressed.ply", []))
#: Longest one splat-transform run may take (seconds).
TIMEOUT = 300


def executable() -> str | None:
    """Path of the splat-transform command, or None when it is not installed."""
    local = REPO / ".npm-tools" / "node_modules" / ".bin" / "splat-transform"
    if local.is_file() and shutil.which("node"):
        return str(local)
    return shutil.which("splat-transform")


def run(exe: str, source: Path, output: Path, extra: list[str] = ()) -> None:
    """``splat-transform -q -w [extra] source output``; raises RuntimeError with its stderr."""
    cmd = [exe, "-q", "-w", *extra, str(source), str(output)]
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=TIMEOUT)
    if proc.returncode != 0 or not output.exists():
        raise RuntimeError(f"{' '.join(cmd)} failed ({proc.returncode}): {proc.stderr[-500:]}")


def stem(source: str) -> str:
    return Path(source).name.split(".")[0]


def generate(out: Path, scenes: Path, exe: str) -> list[Path]:
    """Write every (source, output) pair missing in ``out``; returns all output paths."""
    out.mkdir(parents=True, exist_ok=True)
    written = []
    for source in SOURCES:
        for suffix, extra in OUTPUTS:
            target = out / (stem(source) + suffix)
            if not target.exists():
                tmp = out / (stem(source) + ".partial" + suffix)
                run(exe, scenes / source, tmp, list(extra))
                os.replace(tmp, target)
            written.append(target)
    return written


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--out", type=Path, default=DEFAULT_OUT)
    p.add_argument("--scenes", type=Path, default=Path(
        os.environ.get("SPLATGL_SHARED_SCENES", REPO.parent / "shared" / "scenes")))
    args = p.parse_args(argv)
    exe = executable()
    if exe is None:
        print("splat-transform not found: npm install --prefix .npm-tools "
              "@playcanvas/splat-transform", file=sys.stderr)
        return 2
    for path in generate(args.out, args.scenes, exe):
        print(f"{path} ({path.stat().st_size:,} bytes)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
