"""Loading a 1M-splat SH degree 3 PLY: bounded peak memory and monotone progress.

The load runs in a fresh subprocess under tracemalloc (NumPy reports its buffers to it), so the
peak counts every array the reader and :func:`splatgl.scene.splats.activate` allocate.

Where the memory goes (per splat, SH degree 3, 236 bytes decoded = the Scene's five arrays):
the chunked PLY reader fills the decoded arrays directly (236 B) plus one 64k-row buffer;
activate() validates in blocks of VALIDATE_BLOCK rows (its float64 temporaries exist for one
block at a time) and holds two (N,) masks (2 B).  The Scene adopts the reader's read-only
float32 arrays instead of copying them, so the peak is the decoded size plus about one chunk.
"""

from __future__ import annotations

import json
import subprocess
import sys
import textwrap

import numpy as np
import pytest

from splatgl.formats import ply, ply_write
from splatgl.scene.splats import VALIDATE_BLOCK, Scene

pytestmark = pytest.mark.slow  # a 1M-splat file written, then loaded in a subprocess

N = 1_000_000
DEGREE = 3

_CHILD = textwrap.dedent("""
    import json, sys, time, tracemalloc
    from splatgl.formats import load_scene
    calls = []
    tracemalloc.start()
    base = tracemalloc.get_traced_memory()[0]
    t0 = time.perf_counter()
    scene = load_scene(sys.argv[1], progress=lambda d, t, w: calls.append((d, t, w)))
    seconds = time.perf_counter() - t0
    peak = tracemalloc.get_traced_memory()[1] - base
    arrays = (scene.means, scene.quats, scene.log_scales, scene.opacity_logits, scene.sh)
    print(json.dumps({"peak": peak, "decoded": sum(a.nbytes for a in arrays), "calls": calls,
                      "count": scene.count, "degree": scene.sh_degree, "seconds": seconds}))
""")


@pytest.fixture(scope="module")
def big_load(tmp_path_factory):
    """Write a 1M-splat SH3 PLY with the PLY writer, load it in a subprocess, return figures."""
    rng = np.random.default_rng(7)
    k = (DEGREE + 1) ** 2
    scene = Scene(rng.normal(size=(N, 3)), rng.normal(size=(N, 4)), rng.normal(-4, 1, (N, 3)),
                  rng.normal(size=N), rng.normal(0, 0.3, (N, k, 3)))
    path = tmp_path_factory.mktemp("large") / "big_sh3.ply"
    ply_write.write(path, scene)
    del scene
    proc = subprocess.run([sys.executable, "-c", _CHILD, str(path)], capture_output=True,
                          text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    path.unlink()
    return json.loads(proc.stdout)


def test_loads_every_splat(big_load):
    assert big_load["count"] == N and big_load["degree"] == DEGREE
    assert big_load["decoded"] == N * (3 + 4 + 3 + 1 + 48) * 4


def test_progress_is_monotone_and_ends_at_total(big_load):
    calls = big_load["calls"]
    done = [d for d, _, _ in calls]
    assert len(calls) >= 2 and done[0] == 0 and done[-1] == N
    assert all(t == N for _, t, _ in calls)
    assert all(b > a for a, b in zip(done, done[1:]))
    assert all(w == "reading big_sh3.ply" for _, _, w in calls)


def test_peak_memory_is_the_decoded_arrays_plus_one_chunk(big_load):
    """The reader fills the decoded arrays through one chunk buffer; activate() validates in
    blocks (float64 quaternions and a per-field mask for VALIDATE_BLOCK rows at a time) and
    holds two (N,) bool masks.  Nothing else may be full-size (measured 1.31x before the
    validation was blocked, 1.07x after)."""
    chunk = ply.CHUNK_ROWS * 4 * (3 + 3 + 48 + 1 + 3 + 4)  # one buffer of the file's rows
    block = VALIDATE_BLOCK * 8 * 48  # the largest block temporary (generous: float64 x 48)
    bound = big_load["decoded"] + chunk + block + 2 * N
    assert big_load["peak"] <= bound, (big_load["peak"] / big_load["decoded"], big_load)


def test_peak_memory_at_most_1_1x_the_decoded_size(big_load):
    ratio = big_load["peak"] / big_load["decoded"]
    assert ratio <= 1.1, big_load
