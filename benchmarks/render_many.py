"""Benchmark of `splatgl render --path`: one process for a whole camera path against one
process per frame, and frames per second for PNG, EXR and MP4 output.

    python benchmarks/render_many.py [--scene biker.compressed.ply] [--frames 120]
                                     [--processes 6] [--format-frames 40]

Run it under /work/tools/timed (or on an otherwise idle machine).  It prints a Markdown table:

- batch: `splatgl render SCENE --path orbit:N -o DIR/ --timings` (PNG), its whole wall time
  (process start to exit: import, scene load, context, shaders, N frames) and the sum of the
  per-frame stage times the renderer reports (`last_times.total`, what `--timings` prints);
- separate: P `splatgl render --camera cam_k.json -o k.png --timings` processes for cameras
  spread along the same orbit, their mean wall time extrapolated to N frames (P < N keeps the
  run short; each process does the same work whichever frame it renders);
- EXR and MP4: the same orbit's first F frames through the batch path (frames per second of
  the render loop, i.e. after start-up; PNG's is given the same way).
"""

from __future__ import annotations

import argparse
import os
import platform
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from splatgl.measure.bench.real_scenes import shared_scenes_dir

REPO = Path(__file__).resolve().parent.parent
SHARED = shared_scenes_dir(REPO)
TIMINGS = re.compile(r"timings: ([\d.]+) s for (\d+) frames; renderer stages ([\d.]+) s")
STAGES = re.compile(r"(\w+) ([\d.]+) ms")


def splatgl(*args: str) -> tuple[float, str]:
    t0 = time.perf_counter()
    out = subprocess.run([sys.executable, "-m", "splatgl", "render", *args], capture_output=True, text=True,
                         env={**os.environ, "SPLATGL_PROGRESS": "0"})
    wall = time.perf_counter() - t0
    if out.returncode:
        sys.exit(f"splatgl {' '.join(args)} failed: {out.stderr.strip()}")
    return wall, out.stdout


def batch(scene: Path, frames: int, output: str, width: int, height: int) -> tuple[float, float, float]:
    """(process wall s, render loop s, sum of stage times s)."""
    wall, out = splatgl(str(scene), "--path", f"orbit:{frames}", "--width", str(width),
                        "--height", str(height), "-o", output, "--timings")
    loop, n, stages = TIMINGS.search(out).groups()
    assert int(n) == frames
    return wall, float(loop), float(stages)


def cpu_name() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown CPU"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--scene", type=Path, default=SHARED / "compressed_ply" / "biker.compressed.ply")
    ap.add_argument("--frames", type=int, default=120)
    ap.add_argument("--processes", type=int, default=6)
    ap.add_argument("--format-frames", type=int, default=40)
    ap.add_argument("--width", type=int, default=1280)
    ap.add_argument("--height", type=int, default=720)
    args = ap.parse_args()
    sys.path.insert(0, str(REPO))
    from splatgl.cameras.camera_files import save_camera
    from splatgl.formats import load_scene
    from splatgl.gl.context import create_headless_context
    from splatgl.paths import orbit

    ctx = create_headless_context()
    gl = ctx.info.get("GL_RENDERER", "?")
    ctx.release()
    flags = Path("/proc/cpuinfo").read_text() if Path("/proc/cpuinfo").exists() else ""
    simd = "AVX-512" if "avx512f" in flags else "AVX2" if "avx2" in flags else "no AVX2"
    n, w, h = args.frames, args.width, args.height
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        b_wall, b_loop, b_stages = batch(args.scene, n, str(tmp / "png") + "/", w, h)
        cams = orbit(load_scene(args.scene), n, w, h)
        walls, stage_sums = [], []
        for i in range(args.processes):
            k = i * n // args.processes
            save_camera(tmp / f"cam{k}.json", cams[k])
            wall, out = splatgl(str(args.scene), "--camera", str(tmp / f"cam{k}.json"), "-o", str(tmp / f"one{k}.png"), "--timings")
            times = dict(STAGES.findall(out.split("timings:")[1]))
            stage_sums.append(sum(float(v) for k2, v in times.items() if k2 != "drawn") / 1e3)
            walls.append(wall)
        sep_per_frame = sum(walls) / len(walls)
        fmt = {}
        for name, out in (("EXR", str(tmp / "exr" / "%05d.exr")), ("MP4", str(tmp / "v.mp4"))):
            _, loop, _ = batch(args.scene, args.format_frames, out, w, h)
            fmt[name] = args.format_frames / loop
    print(f"Machine: {cpu_name()} ({simd}, {os.cpu_count()} cores), GL renderer {gl}; "
          f"scene {args.scene.name}, {w}x{h}, orbit of {n} frames.\n")
    print("| measure | value |\n|---|---|")
    print(f"| batch process wall time (import, load, context, shaders, {n} PNG frames) | {b_wall:.1f} s |")
    print(f"| batch render loop (frames rendered and written) | {b_loop:.1f} s ({n / b_loop:.2f} frames/s) |")
    print(f"| sum of per-frame stage times (`--timings`) in the batch | {b_stages:.1f} s |")
    print(f"| **batch wall time / sum of stage times** | **{b_wall / b_stages:.3f}** (loop alone {b_loop / b_stages:.3f}) |")
    print(f"| separate process, mean wall time per frame ({args.processes} processes) | {sep_per_frame:.2f} s |")
    print(f"| separate processes' own stage times, mean per frame | {sum(stage_sums) / len(stage_sums):.3f} s |")
    print(f"| batch wall time / per-frame stage times of separate processes x {n} | "
          f"{b_wall / (n * sum(stage_sums) / len(stage_sums)):.3f} |")
    print(f"| **{n} separate processes (extrapolated) / batch** | **{n * sep_per_frame / b_wall:.2f}x** |")
    print(f"| PNG frames/s (render loop) | {n / b_loop:.2f} |")
    for name, fps in fmt.items():
        print(f"| {name} frames/s (render loop, {args.format_frames} frames) | {fps:.2f} |")


if __name__ == "__main__":
    main()
