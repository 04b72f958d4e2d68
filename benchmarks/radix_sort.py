"""The device radix sort alone against the CPU sort (issue 40, item 2), in one run.

For each size, depth keys like a frame's (float32 bits of view-space depths spread over two
orders of magnitude, a third of them tied, with the cull's ascending splat indices as values),
medians of ``--repeats`` runs after one warm-up of:

- ``cpu``: the CPU sort stage (:func:`splatgl.order.sort.depth_sort`, NumPy's sort of packed
  uint64 keys), what ``--sort exact`` runs;
- ``gpu``: :func:`splatgl.gl.radix_sort.device_depth_sort`, what ``--sort gpu`` runs: upload
  keys and values, sort, read the order back; one row per ranking path the device has;
- ``resident``: the same sort of keys already on the device, nothing read back (what a
  device-resident order pays), to ``glFinish``;
- ``old``: the sort this one replaced (4-bit digits, built from git at ``OLD_COMMIT``), where
  git and that commit are at hand (``--no-old`` leaves it out).

Every result is checked against the CPU order.  Prints the machine line (CPU, SIMD level,
cores, GL renderer); ``--json FILE`` also writes the figures (atomically).  Times depend on
the machine and on what else runs on it: run it on a quiet machine::

    python benchmarks/radix_sort.py --sizes 100k,1M,6M --repeats 7 --json radix.json
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import tempfile
import time
from pathlib import Path

import numpy as np
from _script import run

#: The last commit with the 4-bit sort (shaders radix_count/scan/scatter.comp).
OLD_COMMIT = "ce413bd"
OLD_FILES = ("radix_count.comp", "radix_scan.comp", "radix_scatter.comp", "lib/radix.glsl")
REPO = Path(__file__).resolve().parent.parent


def frame_keys(n: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """(depths (n,) float32 > 0, ascending indices (n,) uint32) like a culled frame's."""
    rng = np.random.default_rng(seed)
    z = np.exp(rng.uniform(np.log(0.5), np.log(60.0), n)).astype(np.float32)
    z[rng.integers(0, n, n // 3)] = z[0] if n else 0
    idx = np.sort(rng.choice(2 * n, n, replace=False)).astype(np.uint32)
    return z, idx


def _median_ms(fn, repeats: int, before=None) -> float:
    """Median milliseconds of ``fn()`` over ``repeats`` runs after one warm-up; ``before()``
    runs untimed ahead of each."""
    times = []
    for i in range(repeats + 1):
        if before:
            before()
        t0 = time.perf_counter()
        fn()
        if i:
            times.append(1e3 * (time.perf_counter() - t0))
    return statistics.median(times)


class OldSorter:
    """The replaced 4-bit sort, its shaders read from git, for this measurement only."""

    BITS, ITEMS, GROUP = 4, 16, 256

    def __init__(self, ctx, folder: Path):
        from splatgl.gl.shaders import preprocess

        defines = {"RADIX_BITS": self.BITS, "RADIX_ITEMS": self.ITEMS, "RADIX_GROUP": self.GROUP}
        self.ctx = ctx
        self.progs = [ctx.compute_shader(preprocess(name, defines, root=folder).text)
                      for name in OLD_FILES[:3]]
        self.bufs = []

    @classmethod
    def from_git(cls, ctx):
        """The old sorter, or None where git or the commit is missing."""
        folder = Path(tempfile.mkdtemp(prefix="old-radix-"))
        (folder / "lib").mkdir()
        try:
            for name in OLD_FILES:
                text = subprocess.run(["git", "-C", str(REPO), "show", f"{OLD_COMMIT}:shaders/{name}"],
                                      capture_output=True, text=True, check=True).stdout
                (folder / name).write_text(text)
        except (OSError, subprocess.CalledProcessError):
            return None
        return cls(ctx, folder)

    def sort_values(self, keys: np.ndarray, values: np.ndarray) -> np.ndarray:
        from splatgl.gl import bindings as b

        count, tile = keys.size, self.GROUP * self.ITEMS
        tiles = -(-count // tile)
        if not self.bufs:
            self.bufs = [self.ctx.buffer(reserve=4 * count) for _ in range(4)]
            self.bufs.append(self.ctx.buffer(reserve=4 * (1 << self.BITS) * tiles))
        k_a, v_a, k_b, v_b, hist = self.bufs
        k_a.write(keys)
        v_a.write(values)
        top = (int(keys.min()) ^ int(keys.max())).bit_length()
        src, dst = (k_a, v_a), (k_b, v_b)
        hist.bind_to_storage_buffer(b.RADIX_BINDING_HIST)
        for shift in range(0, top, self.BITS):
            for buf, point in zip(src + dst, (b.RADIX_BINDING_KEYS_IN, b.RADIX_BINDING_VALS_IN,
                                              b.RADIX_BINDING_KEYS_OUT, b.RADIX_BINDING_VALS_OUT)):
                buf.bind_to_storage_buffer(point)
            for prog, groups in zip(self.progs, (tiles, 1, tiles)):
                for name, value in (("u_count", count), ("u_tiles", tiles), ("u_shift", shift)):
                    if name in prog:
                        prog[name].value = value
                prog.run(group_x=groups)
                self.ctx.memory_barrier()
            src, dst = dst, src
        return np.frombuffer(src[1].read(4 * count), np.uint32)

    def release(self) -> None:
        for obj in self.bufs + self.progs:
            obj.release()


def measure(renderer, n: int, repeats: int, old: bool) -> list[dict]:
    from splatgl.gl.radix_sort import RadixSorter, device_depth_sort, subgroup_paths
    from splatgl.splatmath.radix import radix_passes
    from splatgl.order.sort import depth_sort

    z, idx = frame_keys(n)
    keys = z.view(np.uint32)
    want = depth_sort(z, idx)
    cpu = _median_ms(lambda: depth_sort(z, idx), repeats)
    passes = len(radix_passes(keys))
    rows = [dict(splats=n, sort="cpu", path="-", passes=passes, ms=cpu, over_cpu=1.0,
                 identical=True)]
    for path in subgroup_paths(renderer.ctx):
        sorter = RadixSorter(renderer.ctx, renderer.programs, path=path)
        try:
            got = device_depth_sort(sorter, z, idx)
            ok = bool(np.array_equal(got, want))
            ms = _median_ms(lambda: device_depth_sort(sorter, z, idx), repeats)
            k_a, v_a = sorter.buffers()

            def upload():
                k_a.write(keys)
                v_a.write(idx)
                renderer.ctx.finish()

            def resident():
                sorter.sort_buffers(n)
                renderer.ctx.finish()
            res = _median_ms(resident, repeats, before=upload)
        finally:
            sorter.release()
        label = f"{path}, warp {sorter.warp}{', narrow' if sorter.narrow else ''}"
        rows.append(dict(splats=n, sort="gpu", path=label, passes=passes, ms=ms,
                         over_cpu=ms / cpu, identical=ok))
        rows.append(dict(splats=n, sort="resident", path=label, passes=passes, ms=res,
                         over_cpu=res / cpu, identical=ok))
    if old:
        sorter = OldSorter.from_git(renderer.ctx)
        if sorter is not None:
            try:
                ok = bool(np.array_equal(sorter.sort_values(keys, idx), want))
                ms = _median_ms(lambda: sorter.sort_values(keys, idx), repeats)
            finally:
                sorter.release()
            rows.append(dict(splats=n, sort="old", path=f"git {OLD_COMMIT}",
                             passes=len(range(0, (int(keys.min()) ^ int(keys.max())).bit_length(), 4)),
                             ms=ms, over_cpu=ms / cpu, identical=ok))
    return rows


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--sizes", default="100k,1M,6M", help="key counts, 'k'/'M' suffixes")
    p.add_argument("--repeats", type=int, default=7, help="timed runs per figure (median)")
    p.add_argument("--no-old", action="store_true", help="leave out the replaced 4-bit sort")
    p.add_argument("--json", default=None, metavar="FILE", help="also write the figures here")
    args = p.parse_args()
    if args.repeats < 1:
        p.error(f"--repeats must be at least 1, got {args.repeats}")
    from splatgl.api import Renderer
    from splatgl.measure.bench.machine import describe, machine_info
    from splatgl.measure.bench.scale import parse_sizes
    from splatgl.gl.context import renderer_name
    from splatgl.writing.atomic import atomic_write_text

    sizes = parse_sizes(args.sizes, (100_000, 1_000_000, 6_000_000), "--sizes")
    with Renderer() as renderer:
        machine = machine_info(renderer_name(renderer.ctx))
        print(describe(machine), flush=True)
        print(f"# medians of {args.repeats} runs; ms; gpu = upload, sort, read the order back; "
              "resident = the sort alone", flush=True)
        print(f"{'keys':>10} {'sort':>9} {'path':>22} {'passes':>6} {'ms':>9} {'/cpu':>6} same")
        rows = []
        for n in sizes:
            for r in measure(renderer, n, args.repeats, not args.no_old):
                rows.append(r)
                print(f"{r['splats']:>10,} {r['sort']:>9} {r['path']:>22} {r['passes']:>6} "
                      f"{r['ms']:>9.1f} {r['over_cpu']:>6.2f} {'yes' if r['identical'] else 'NO'}",
                      flush=True)
    if args.json:
        atomic_write_text(args.json, json.dumps({"machine": machine, "repeats": args.repeats,
                                                 "rows": rows}, indent=1))


if __name__ == "__main__":
    run(main)
