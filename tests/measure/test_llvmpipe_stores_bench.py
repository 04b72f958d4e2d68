"""benchmarks/llvmpipe_stores.py (the storage-write floor under issue 40's llvmpipe sort target)
at a tiny size, one round: every variant timed, the scatter's order checked by the script
itself, the floor lines printed, and its refusal of bad options."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
SCRIPT = REPO / "benchmarks" / "llvmpipe_stores.py"


def _run(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, str(SCRIPT), *args], capture_output=True, text=True,
                          timeout=300, cwd=REPO / "benchmarks")


def test_tiny_run_times_every_variant_and_prints_the_floor():
    done = _run("--keys", "4096", "--bits", "6", "--repeats", "1", "--lanes", "16")
    assert done.returncode == 0, done.stderr
    out = done.stdout
    assert out.startswith("machine: ") and "# 4,096 keys, 16 lanes, 6-bit digits" in out
    for name in ("seq uint", "seq uvec2", "seq uvec4", "scatter none", "scatter key",
                 "scatter uvec2", "scatter two", "numpy sort"):
        assert f"{name:>14} " in out, name
    assert out.count("# LSD floor, ") == 2 and "x NumPy's sort" in out


def test_bad_options_are_one_line():
    done = _run("--lanes", "12")
    assert done.returncode == 2 and "--lanes must be a positive multiple of 8" in done.stderr
