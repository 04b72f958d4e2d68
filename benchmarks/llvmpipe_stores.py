"""What a radix sort pass's storage writes cost on this OpenGL device (issue 40 item 2's floor).

The block passes (splatgl/gl/radix_block.py) spend most of a sort in the scatter, one storage
write a key a pass.  Mesa's llvmpipe (22.3) runs every storage write whose address differs
between lanes as a loop over the SIMD lanes, whatever the address pattern.  This script times
that write alone, on 1M keys by default, in kernels shaped like the scatter (32 lanes, each
walking its own contiguous block; ``--lanes``), each variant a separate compute shader, all in
one process, interleaved round by round (medians of ``--repeats``):

- ``seq uint`` / ``seq uvec2`` / ``seq uvec4``: each lane writes its block in order (one uint,
  one pair, or four uints a write): the write itself, no cache misses;
- ``scatter none`` / ``key`` / ``uvec2`` / ``two``: the scatter pass of ``--bits``-bit digits
  as the sorter runs it (each lane reads 4 keys a storage read, looks up and bumps its digit's
  next place in a private array) writing nothing, the key alone, the (key, value) pair as one
  ``uvec2`` (what the sorter writes), or key and value to two buffers;

and NumPy's sort of the same keys packed as uint64 with their indices (the CPU order's sort,
``splatgl.order.sort``) for scale.  The last lines estimate an LSD sort's floor from these:
passes x (scatter uvec2 + count), where a count pass costs what ``scatter none`` does, and the
same with the scatter's writes as cheap as ``seq uvec2``'s (no cache misses at all).  The
scatter's destinations are checked once against NumPy's stable argsort of the digits.

    python benchmarks/llvmpipe_stores.py [--keys 1M] [--bits 11] [--repeats 7]

Prints the machine line (CPU, SIMD level, cores, GL renderer) and the load average; run it on a
quiet machine: the two cores are shared by llvmpipe's threads and everything else.
"""

from __future__ import annotations

import argparse
import os
import statistics
import time

import numpy as np
from _script import run

HEADER = "#version 430\nlayout(local_size_x = 8) in;\nuniform uint u_per;\n"
SEQUENTIAL = {
    "seq uint": ("uint o[]", "for (uint i = 0u; i < u_per; ++i) o[lo + i] = i ^ lane;", 1),
    "seq uvec2": ("uvec2 o[]", "for (uint i = 0u; i < u_per; ++i) o[lo + i] = uvec2(i, lane);", 1),
    "seq uvec4": ("uvec4 o[]", "for (uint i = 0u; i < u_per / 4u; ++i) "
                               "o[lo / 4u + i] = uvec4(i, lane, i, lane);", 4),
}
SCATTER_BODY = """
layout(std430, binding = 0) readonly buffer K { uvec4 keys[]; };
layout(std430, binding = 2) readonly buffer S { uint starts[]; };
OUT
void main() {
    uint lane = gl_GlobalInvocationID.x, lo = lane * u_per;
    uint h[R];
    for (uint d = 0u; d < R; ++d) h[d] = starts[lane * R + d];
    for (uint i = lo; i < lo + u_per; i += 4u) {
        uvec4 k4 = keys[i >> 2];
        for (int c = 0; c < 4; ++c) {
            uint key = k4[c], d = key & (R - 1u), at = h[d];
            h[d] = at + 1u;
            STORE;
        }
    }
}
"""
SCATTERS = {
    "scatter none": ("layout(std430, binding = 1) writeonly buffer O { uint o[]; };",
                     "if (at == 0xFFFFFFFFu) o[0] = key"),
    "scatter key": ("layout(std430, binding = 1) writeonly buffer O { uint o[]; };", "o[at] = key"),
    "scatter uvec2": ("layout(std430, binding = 1) writeonly buffer O { uvec2 o[]; };",
                      "o[at] = uvec2(key, i + uint(c))"),
    "scatter two": ("layout(std430, binding = 1) writeonly buffer O { uint o[]; };\n"
                    "layout(std430, binding = 3) writeonly buffer V { uint v[]; };",
                    "o[at] = key; v[at] = i + uint(c)"),
}


def _count(text: str) -> int:
    text = text.strip().upper()
    scale = {"K": 1000, "M": 1000 ** 2}.get(text[-1:], 1)
    return int(float(text.rstrip("KM")) * scale)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--keys", default="1M", help="keys ('k'/'M' suffixes; default 1M)")
    parser.add_argument("--bits", type=int, default=11, help="digit bits of the scatter (default 11)")
    parser.add_argument("--lanes", type=int, default=32, help="lanes, a multiple of 8 (default 32)")
    parser.add_argument("--repeats", type=int, default=7, help="timed rounds (medians)")
    args = parser.parse_args()
    if args.lanes % 8 or args.lanes <= 0 or not 4 <= args.bits <= 14 or args.repeats < 1:
        parser.error("--lanes must be a positive multiple of 8, --bits 4-14, --repeats >= 1")
    from splatgl.gl.context import create_headless_context, renderer_name
    from splatgl.measure.bench.machine import describe, machine_info

    lanes, radix = args.lanes, 1 << args.bits
    per = -(-_count(args.keys) // (4 * lanes)) * 4          # keys a lane, whole uvec4s
    n = per * lanes
    rng = np.random.default_rng(0)
    keys = rng.integers(0, 2 ** 32, n, dtype=np.uint32)
    digits = (keys & np.uint32(radix - 1)).reshape(lanes, per)
    counts = np.stack([np.bincount(row, minlength=radix) for row in digits], 1)  # (digit, lane)
    starts = (np.cumsum(counts.ravel()) - counts.ravel()).reshape(radix, lanes).T
    ctx = create_headless_context()
    print(describe(machine_info(renderer_name(ctx))), flush=True)
    load = os.getloadavg()
    bufs = {"keys": ctx.buffer(keys.tobytes()), "out": ctx.buffer(reserve=16 * n),
            "starts": ctx.buffer(np.ascontiguousarray(starts, np.uint32).tobytes()),
            "vals": ctx.buffer(reserve=4 * n)}
    programs = {}
    for name, (decl, loop, _) in SEQUENTIAL.items():
        programs[name] = ctx.compute_shader(
            HEADER + f"layout(std430, binding = 1) writeonly buffer O {{ {decl}; }};\n"
            f"void main() {{ uint lane = gl_GlobalInvocationID.x, lo = lane * u_per; {loop} }}\n")
    for name, (out, store) in SCATTERS.items():
        body = SCATTER_BODY.replace("OUT", out).replace("STORE", store)
        programs[name] = ctx.compute_shader(HEADER + f"#define R {radix}u\n" + body)
    for prog in programs.values():
        prog["u_per"].value = per
    for point, name in enumerate(("keys", "out", "starts", "vals")):
        bufs[name].bind_to_storage_buffer(point)
    packed = (keys.astype(np.uint64) << np.uint64(32)) | np.arange(n, dtype=np.uint64)
    times: dict[str, list[float]] = {name: [] for name in [*programs, "numpy sort"]}
    for round_ in range(args.repeats + 1):                  # round 0: the warm-up
        for name, prog in programs.items():
            ctx.finish()
            t0 = time.perf_counter()
            prog.run(group_x=lanes // 8)
            ctx.finish()
            if round_:
                times[name].append(1e3 * (time.perf_counter() - t0))
            if round_ == 0 and name == "scatter key":
                got = np.frombuffer(bufs["out"].read(4 * n), np.uint32)
                expect = keys[np.argsort(keys & np.uint32(radix - 1), kind="stable")]
                if not np.array_equal(got, expect):
                    raise SystemExit("llvmpipe_stores.py: the scatter wrote a wrong order")
        t0 = time.perf_counter()
        np.sort(packed)
        if round_:
            times["numpy sort"].append(1e3 * (time.perf_counter() - t0))
    med = {name: statistics.median(v) for name, v in times.items()}
    print(f"# {n:,} keys, {lanes} lanes, {args.bits}-bit digits; medians of {args.repeats} "
          f"interleaved rounds, ms; load average {load[0]:.2f} at the start, "
          f"{os.getloadavg()[0]:.2f} at the end")
    # CPU time: llvmpipe runs a dispatch on LP_NUM_THREADS threads (default: one a core), busy
    # throughout here; NumPy's sort on one
    threads = int(os.environ.get("LP_NUM_THREADS") or os.cpu_count() or 1)
    for name, ms in med.items():
        share = 1 if name == "numpy sort" else threads
        if name.startswith("seq"):
            writes = n // SEQUENTIAL[name][2]
            print(f"{name:>14} {ms:8.2f}  {1e6 * ms * share / writes:6.1f} ns CPU a write "
                  f"({writes:,} writes)")
        else:
            print(f"{name:>14} {ms:8.2f}  {1e6 * ms * share / n:6.1f} ns CPU a key")
    scatter, count, sort = med["scatter uvec2"], med["scatter none"], med["numpy sort"]
    ideal = count + med["seq uvec2"]     # the scatter's work with every write in order
    for passes in (2, 3):
        floor, best = passes * (scatter + count), passes * (ideal + count)
        print(f"# LSD floor, {passes} passes of (scatter uvec2 + count): {floor:.1f} ms "
              f"= {floor / sort:.2f}x NumPy's sort (no scan, no key bits, no plan); with every "
              f"write in order (no cache miss): {best:.1f} ms = {best / sort:.2f}x")


if __name__ == "__main__":
    run(main)
