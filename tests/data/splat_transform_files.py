#!/usr/bin/env python3
"""Generate interoperability test files with splat-transform (PlayCanvas) from the shared scenes.

    python tests/data/splat_transform_files.py [--version V] [--out DIR] [--scenes DIR]

Writes, for each pinned splat-transform version (:data:`VERSIONS`) and each source scene below,
``<stem>.sog``, ``<stem>.spz`` (SPZ version 3), ``<stem>.v4.spz``, ``<stem>.glb`` and
``<stem>.compressed.ply`` into ``tests/data/splat-transform/<version>/`` (git-ignored:
regenerated, never committed).  Each version is installed by .ci/run into its own prefix,
``.npm-tools/st<digits>`` (``npm install --prefix .npm-tools/st271
@playcanvas/splat-transform@2.7.1``; 3.x asks for Node >= 22 but runs on Node 20 when
installed by version).  tests/formats/test_interop_splat_transform.py calls :func:`generate` itself
when the files are missing and the tool is present, and skips with the reason otherwise.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
DEFAULT_OUT = REPO / "tests" / "data" / "splat-transform"
#: The pinned splat-transform versions: 2.7.1 (the last 2.x: SPZ through the official library
#: in the specification's RUB) and 3.7.0 (npm's latest when pinned: PLY's RDF unconverted).
VERSIONS = ("2.7.1", "3.7.0")
#: Source scenes (relative to the shared scenes folder): an SH-0 PLY and an SH-3 compressed PLY.
SOURCES = ("ply/donut_sh0.ply", "fixtures/test64_sh3.compressed.ply")
#: Output suffixes and the extra splat-transform arguments for each (SOG: k-means on the CPU,
#: as no GPU adapter need exist).
OUTPUTS = ((".sog", ["-g", "cpu"]), (".spz", ["--spz-version", "3"]),
           (".v4.spz", ["--spz-version", "4"]), (".glb", []), (".compressed.ply", []))
#: Longest one splat-transform run may take (seconds).
TIMEOUT = 300


def prefix(version: str) -> Path:
    """The npm prefix splat-transform ``version`` is installed into."""
    return REPO / ".npm-tools" / ("st" + version.replace(".", ""))


def missing(version: str) -> str | None:
    """Why splat-transform ``version`` cannot run here, or None when it can."""
    if shutil.which("node") is None:
        return "node is not installed"
    package = prefix(version) / "node_modules" / "@playcanvas" / "splat-transform" / "package.json"
    install = (f"npm install --prefix .npm-tools/{prefix(version).name} "
               f"@playcanvas/splat-transform@{version}")
    if not package.is_file():
        return f"splat-transform {version} not installed ({install})"
    found = json.loads(package.read_text()).get("version")
    if found != version:
        return f"{prefix(version).name} holds splat-transform {found}, not {version} ({install})"
    return None


def executable(version: str) -> str | None:
    """Path of splat-transform ``version``'s command, or None when it cannot run here."""
    if missing(version):
        return None
    return str(prefix(version) / "node_modules" / ".bin" / "splat-transform")


def library(version: str) -> Path:
    """The official SPZ library (WebAssembly, ``@adobe/spz``) inside splat-transform ``version``."""
    return prefix(version) / "node_modules" / "@adobe" / "spz" / "dist" / "spz.js"


def run(exe: str, source: Path, output: Path, extra: list[str] = ()) -> None:
    """``splat-transform -q -w [extra] source output``; raises RuntimeError with its stderr."""
    cmd = [exe, "-q", "-w", *extra, str(source), str(output)]
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=TIMEOUT)
    if proc.returncode != 0 or not output.exists():
        raise RuntimeError(f"{' '.join(cmd)} failed ({proc.returncode}): {proc.stderr[-500:]}")


def out_dir(version: str, root: Path = DEFAULT_OUT) -> Path:
    return root / version


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
    p.add_argument("--version", choices=VERSIONS, action="append",
                   help="splat-transform version (repeatable; default: all)")
    p.add_argument("--out", type=Path, default=DEFAULT_OUT, help="root; one folder per version")
    p.add_argument("--scenes", type=Path, default=Path(
        os.environ.get("SPLATGL_SHARED_SCENES", REPO.parent / "shared" / "scenes")))
    args = p.parse_args(argv)
    status = 0
    for version in args.version or VERSIONS:
        why = missing(version)
        if why:
            print(why, file=sys.stderr)
            status = 2
            continue
        for path in generate(out_dir(version, args.out), args.scenes, executable(version)):
            print(f"{path} ({path.stat().st_size:,} bytes)")
    return status


if __name__ == "__main__":
    sys.exit(main())
