"""The device radix sort alone against the CPU sort (issue 40, item 2), in one run.

For each size, depth keys like a frame's (float32 bits of view-space depths spread over two
orders of magnitude, a third of them tied, with the cull's ascending splat indices as values),
medians of ``--repeats`` rounds after one warm-up round.  A round runs every variant once, one
after the other (interleaved), so a machine whose load changes during the run shifts all of
them alike; the ratios to ``cpu`` (``/cpu``) are the figures to quote:

- ``cpu``: the CPU sort stage (:func:`splatgl.order.sort.depth_sort`, NumPy's sort of packed
  uint64 keys), what ``--sort exact`` runs;
- ``gpu``: :func:`splatgl.gl.radix_sort.device_depth_sort`, what ``--sort gpu`` runs: upload
  keys and values, sort, read the order back;
- ``resident``: the same sort of keys already on the device, its key bits found on the device,
  nothing read back (what a device-resident order pays), to ``glFinish``;
- ``old``: the sort this one replaced (4-bit digits, built from git at ``OLD_COMMIT``), where
  git and that commit are at hand (``--no-old`` leaves it out).

One ``gpu`` and one ``resident`` row per sort design and ranking path the device has
(``--paths``): ``block`` (the block passes, software devices' default, gl/radix_block.py), and
the work-group design's ``khr``, ``arb``, ``portable`` (GPUs' default: the best of them).
Every result is checked against the CPU order.  Prints the machine line (CPU, SIMD level,
cores, GL renderer) and the load average before and after; ``--json FILE`` also writes the
figures (atomically).

Times depend on the machine and on what else runs on it.  For figures to publish, run it on
a quiet machine (load average near 0; nothing else running), all sizes, 7 repeats::

    python benchmarks/radix_sort.py --repeats 7 --json docs/results/radix-sort-MACHINE-DATE.json

(sizes 100k, 1M and 6M by default; about 5 minutes on a 2-core llvmpipe machine).
"""

from __future__ import annotations

import argparse
import json
import os
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


def _timed(fn, before=None) -> float:
    """Milliseconds of one ``fn()``; ``before()`` runs untimed ahead of it."""
    if before:
        before()
    t0 = time.perf_counter()
    fn()
    return 1e3 * (time.perf_counter() - t0)


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


def default_paths(ctx) -> list[str]:
    """The designs and ranking paths this device has: the block passes first on software
    devices (their default), then the work-group design's paths (on GPUs, only those)."""
    from splatgl.gl.egl_devices import is_software_renderer
    from splatgl.gl.radix_sort import BLOCK, subgroup_paths

    software = is_software_renderer(ctx.info.get("GL_RENDERER", ""))
    return ([BLOCK] if software else []) + subgroup_paths(ctx)


def _variants(renderer, n: int, z, idx, paths: list[str], old: bool):
    """(name, path label, passes, run, before, sorter or None, result check) per variant."""
    from splatgl.gl.radix_sort import RadixSorter, device_depth_sort
    from splatgl.order.sort import depth_sort
    from splatgl.splatmath.radix import radix_passes

    keys = z.view(np.uint32)
    out = [("cpu", "-", len(radix_passes(keys)), lambda: depth_sort(z, idx), None, None)]
    for path in paths:
        sorter = RadixSorter(renderer.ctx, renderer.programs, path=path)
        label = f"{path}, warp {sorter.warp}{', narrow' if sorter.narrow else ''}"
        if path == "block":
            label = f"block, {sorter._block.groups} groups"
        passes = len(radix_passes(keys, sorter.digit_bits))
        sorter.reserve(n)
        k_a, v_a = sorter.buffers()

        def upload(k_a=k_a, v_a=v_a):
            k_a.write(keys)
            v_a.write(idx)
            renderer.ctx.finish()

        def resident(sorter=sorter):
            sorter.sort_buffers(n)
            renderer.ctx.finish()

        def resident_result(v_a=v_a):
            return np.frombuffer(v_a.read(4 * n), np.uint32)
        out.append(("gpu", label, passes, lambda s=sorter: device_depth_sort(s, z, idx), None,
                    sorter))
        out.append(("resident", label, passes, resident, upload, resident_result))
    if old:
        sorter = OldSorter.from_git(renderer.ctx)
        if sorter is not None:
            top = (int(keys.min()) ^ int(keys.max())).bit_length()
            out.append(("old", f"git {OLD_COMMIT}", len(range(0, top, 4)),
                        lambda s=sorter: s.sort_values(keys, idx), None, sorter))
    return out


def measure(renderer, n: int, repeats: int, paths: list[str], old: bool) -> list[dict]:
    from splatgl.order.sort import depth_sort

    z, idx = frame_keys(n)
    want = depth_sort(z, idx)
    variants = _variants(renderer, n, z, idx, paths, old)
    times: list[list[float]] = [[] for _ in variants]
    same = []
    try:
        for sort, _, _, fn, before, check in variants:  # the warm-up round, checked
            if sort in ("cpu", "resident"):
                _timed(fn, before)
                same.append(sort == "cpu" or bool(np.array_equal(check(), want)))
            else:
                same.append(bool(np.array_equal(fn(), want)))
        for _ in range(repeats):  # rounds: every variant once, one after the other
            for i, (_, _, _, fn, before, _) in enumerate(variants):
                times[i].append(_timed(fn, before))
    finally:
        for sort, _, _, _, _, owner in variants:
            if sort in ("gpu", "old") and owner is not None:
                owner.release()
    cpu = statistics.median(times[0])
    return [dict(splats=n, sort=sort, path=label, passes=passes, ms=statistics.median(t),
                 over_cpu=statistics.median(t) / cpu, identical=ok)
            for (sort, label, passes, *_), t, ok in zip(variants, times, same)]


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                epilog=__doc__[__doc__.index("Times depend"):],
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--sizes", default="100k,1M,6M", help="key counts, 'k'/'M' suffixes")
    p.add_argument("--repeats", type=int, default=7, help="timed rounds per size (medians)")
    p.add_argument("--paths", default=None,
                   help="sort designs/ranking paths, comma-separated (block, khr, arb, portable; "
                        "default: all the device has, block only on software devices)")
    p.add_argument("--no-old", action="store_true", help="leave out the replaced 4-bit sort")
    p.add_argument("--json", default=None, metavar="FILE", help="also write the figures here")
    args = p.parse_args()
    if args.repeats < 1:
        p.error(f"--repeats must be at least 1, got {args.repeats}")
    from splatgl.api import Renderer
    from splatgl.gl.context import renderer_name
    from splatgl.gl.radix_sort import BLOCK, PATHS
    from splatgl.measure.bench.machine import describe, machine_info
    from splatgl.measure.bench.scale import parse_sizes
    from splatgl.writing.atomic import atomic_write_text

    sizes = parse_sizes(args.sizes, (100_000, 1_000_000, 6_000_000), "--sizes")
    paths = None
    if args.paths:
        paths = [x.strip() for x in args.paths.split(",") if x.strip()]
        bad = [x for x in paths if x not in PATHS + (BLOCK,)]
        if bad:
            p.error(f"--paths: unknown {', '.join(bad)} (expected {', '.join((BLOCK,) + PATHS)})")
    load_before = os.getloadavg()
    with Renderer() as renderer:
        machine = machine_info(renderer_name(renderer.ctx))
        paths = paths or default_paths(renderer.ctx)
        print(describe(machine), flush=True)
        print(f"# load average {load_before[0]:.2f} (1 min), {load_before[1]:.2f} (5 min) at the "
              f"start; medians of {args.repeats} interleaved rounds; ms; gpu = upload, sort, "
              "read the order back; resident = the sort alone", flush=True)
        print(f"{'keys':>10} {'sort':>9} {'path':>22} {'passes':>6} {'ms':>9} {'/cpu':>6} same")
        rows = []
        for n in sizes:
            for r in measure(renderer, n, args.repeats, paths, not args.no_old):
                rows.append(r)
                print(f"{r['splats']:>10,} {r['sort']:>9} {r['path']:>22} {r['passes']:>6} "
                      f"{r['ms']:>9.1f} {r['over_cpu']:>6.2f} {'yes' if r['identical'] else 'NO'}",
                      flush=True)
    load_after = os.getloadavg()
    print(f"# load average {load_after[0]:.2f} (1 min) at the end", flush=True)
    if args.json:
        atomic_write_text(args.json, json.dumps({
            "machine": machine, "repeats": args.repeats, "interleaved": True,
            "load_average": {"start": list(load_before), "end": list(load_after)},
            "rows": rows}, indent=1))


if __name__ == "__main__":
    run(main)
