"""Scenes larger than memory, measured (``splatgl bench --scale --lod``, issue 41 item 6).

For each size the scene is written to a scratch folder a block of rows at a time from the shared
real scenes (:func:`splatgl.measure.bench.scale_lod_steps.write_tiled_scene`: never whole in memory),
then each step runs in its own process (:mod:`splatgl.measure.bench.scale_lod_steps`), which reports its
own time and peak resident memory (VmHWM); the time of the whole process (interpreter start
to exit: a cold start) is measured here too.  Steps: the scene file, the out-of-core level of
detail under ``memory`` (``splatgl lod --memory``), the lazy open, the first frame of the
whole-scene view streamed under ``memory``, the same for the far view (6x the framing
distance), both views at full detail where the scene fits in memory (else "does not fit") and
the PSNRs, the viewer's flight over the streamed scene (its own session and frame-time
budget, ``view --memory``'s: moving frame rate, time from rest to the exact frame, resident
memory and chunks loaded over time), and a path of ``path_frames`` exact frames orbiting the
scene (``render --path --memory``'s: the resident memory after each frame).

Every result is written to ``scale-lod.json`` as it is made (a Ctrl-C keeps what was
measured), and ``scale-lod.png`` (memory and time against size, log axes; the flight's memory
over time) after each size.  The
scene and level-of-detail files are removed after each size unless ``keep_scenes``; those
already in a given ``scratch`` folder are used again instead of built, and left there
(:mod:`splatgl.measure.bench.scale_lod_reuse`: ``--scratch DIR``).
"""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
import tempfile
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

from ...errors import SplatglError
from ...lod.budget import default_budget, format_size
from .real_scenes import REAL_SOURCES, shared_scenes_dir, shared_scenes_help
from .scale_lod_reuse import Found, find, record_path, reused_steps, write_record

#: Default sizes (splats).
SIZES = (1_000_000, 5_000_000, 20_000_000, 100_000_000)
#: Bytes of one SH0 row of the scene PLY (x y z, normals, DC, opacity, 3 scales, 4 rotation).
ROW_BYTES = 68
#: Disk for one size: the scene, the level of detail (about 1.4x) and the build's temporaries
#: (about 1.2x the scene), in scene bytes.
DISK_FACTOR = 3.6
#: A full-detail render's memory: a fixed part (driver, framebuffers) and bytes a splat
#: (measured by ``bench --scale``: 2.0 GB at 6M SH0), against the memory available.
FULL_FIXED, FULL_PER_SPLAT = 250e6, 350.0
#: Seconds between polls of a step's resident memory.
POLL_S = 0.05
#: Memory left to the rest of the machine: a step is stopped at MemAvailable (at the start of
#: the run) less this.
HEADROOM = 2 << 30


@dataclass(frozen=True)
class ScaleLodOptions:
    """sizes: splats per scene.  memory: bytes of the build's and the streaming's budget
    (default: ``splatgl lod --memory``'s, :func:`splatgl.lod.budget.default_budget`).
    width, height: frames.  scratch: folder of the scene files (default: a new folder in the
    temp dir); a size's scene and level of detail already there, complete, are used again
    (:mod:`.scale_lod_reuse`; a stale one is refused).  keep_scenes: leave them there.
    available: bytes of memory a full-detail render may use (default: MemAvailable).  speed:
    the flight's speed (tests fly faster).  path_frames: frames of the path step (a render
    --path streamed under ``memory``: whether its memory stays flat; 0 leaves it out).
    branching: of the level of detail.  block: rows of the scene written at a time."""

    sizes: tuple[int, ...] = SIZES
    memory: int = field(default_factory=lambda: default_budget()[0])
    width: int = 1280
    height: int = 720
    scratch: Path | None = None
    keep_scenes: bool = False
    available: int | None = None
    speed: float = 1.0
    path_frames: int = 60
    branching: int = 4
    block: int = 1_000_000


def mem_available() -> int:
    """MemAvailable of /proc/meminfo in bytes (0 where unknown)."""
    try:
        for line in open("/proc/meminfo"):
            if line.startswith("MemAvailable:"):
                return int(line.split()[1]) * 1024
    except OSError:
        pass
    return 0


def disk_need(sizes, keep: bool, found=None) -> int:
    """Bytes of scratch disk the run needs: the largest size's files (all of them with
    ``keep``, which leaves every size's scene and level of detail), less the files ``found``
    (size -> :class:`~.scale_lod_reuse.Found`) already there, which are used again."""
    found = found or {}

    def files(n):   # (the files written, the build's temporaries) in scene bytes
        f = found.get(n)
        lod = not (f and f.lod)
        return (0.0 if f and f.scene else 1.0) + (1.4 if lod else 0.0), 1.2 if lod else 0.0

    if keep:   # every scene and level of detail stays; one build's temporaries at a time
        return int(sum(n * ROW_BYTES * files(n)[0] for n in sizes)
                   + max(n * ROW_BYTES * files(n)[1] for n in sizes))
    return int(max(n * ROW_BYTES * sum(files(n)) for n in sizes))   # DISK_FACTOR with none found


def check_disk(folder: Path, sizes, keep: bool, found=None) -> None:
    """One line when ``folder``'s file system lacks the room :func:`disk_need` names."""
    need = disk_need(sizes, keep, found)
    if need == 0:
        return
    probe = next(p for p in (folder, *folder.parents) if p.exists())
    free = shutil.disk_usage(probe).free
    if free < need:
        raise SplatglError(f"--scale --lod: {probe} has {format_size(free)} free, the scenes of "
                           f"--sizes and their levels of detail need about {format_size(need)}: "
                           "choose smaller --sizes or another TMPDIR")


def full_fits(n: int, available: int) -> tuple[bool, str]:
    """Whether the full-detail render of ``n`` splats fits in ``available`` bytes, and why not."""
    need = FULL_FIXED + FULL_PER_SPLAT * n
    if need <= available:
        return True, ""
    return False, f"does not fit: about {format_size(int(need))} needed, {format_size(available)} available"


class StepFailed(Exception):
    pass


def _rss(pid: int) -> int:
    """Resident bytes of process ``pid`` now (0 once it is gone)."""
    try:
        for line in open(f"/proc/{pid}/status"):
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) * 1024
    except OSError:
        pass
    return 0


def run_step(step: str, args: dict, cap: int = 0) -> dict:
    """One step in a fresh process: its JSON plus ``wall_s`` (process start to exit).  ``cap``:
    resident bytes past which the process is killed (polled; 0: none), so a step that would
    not fit fails alone instead of taking the machine's memory."""
    t0 = time.perf_counter()
    with tempfile.TemporaryFile("w+") as out, tempfile.TemporaryFile("w+") as err:
        proc = subprocess.Popen([sys.executable, "-m", "splatgl.measure.bench.scale_lod_steps", step,
                                 json.dumps(args)], stdout=out, stderr=err, text=True)
        try:
            while proc.poll() is None:
                if cap and _rss(proc.pid) > cap:
                    proc.kill()
                    proc.wait()
                    raise StepFailed(f"stopped at {format_size(cap)} resident (the cap: "
                                     "MemAvailable at the start less 2 GiB)")
                time.sleep(POLL_S)
        finally:
            if proc.poll() is None:   # Ctrl-C here: the child goes too
                proc.kill()
                proc.wait()
        wall = time.perf_counter() - t0
        out.seek(0)
        err.seek(0)
        stdout, stderr = out.read(), err.read()
    if proc.returncode != 0:
        tail = (stderr.strip().splitlines() or [f"exit code {proc.returncode}"])[-1]
        raise StepFailed(tail)
    return {**json.loads(stdout.strip().splitlines()[-1]), "wall_s": wall}


def _psnr(a_path: Path, b_path: Path) -> float | None:
    import numpy as np

    from ..evaluation.metrics import psnr

    value = float(psnr(np.load(a_path), np.load(b_path)))
    return None if value == float("inf") else value


def measure_size(n: int, options: ScaleLodOptions, folder: Path, row: dict, save, log,
                 found: Found = Found()) -> None:
    """Every step of the ``n``-splat scene into ``row`` (``save()`` after each); the files
    ``found`` in ``folder`` are used again (:mod:`.scale_lod_reuse`), never removed."""
    scene, lod = folder / f"scale-{n}.ply", folder / f"scale-{n}.lod.ply"
    common = {"scene": str(scene), "lod": str(lod), "memory": options.memory,
              "shared": str(shared_scenes_dir()),
              "width": options.width, "height": options.height}
    available = options.available if options.available is not None else mem_available()
    fits, why = full_fits(n, available)
    cap = max(available - HEADROOM, 1 << 30) if available else 0
    images = {k: folder / f"{k.replace(' ', '-')}-{n}.npy" for k in ("frame", "far", "full", "full far")}
    steps = [("scene", {"splats": n, "block": options.block}),
             ("build", {"branching": options.branching}), ("open", {}),
             ("frame", {"image": str(images["frame"])}),
             ("far", {"image": str(images["far"]), "far": True})]
    steps += [("full", {"image": str(images["full"]), "far_image": str(images["full far"])})
              ] if fits else []
    steps += [("flight", {"speed": options.speed})]
    steps += [("path", {"frames": options.path_frames})] if options.path_frames else []
    if not fits:
        row["full"] = {"skipped": why}
    reused = reused_steps(folder, n, found)
    try:
        for step, extra in steps:
            if step in reused:
                row[step] = reused[step]
                log(f"scale-lod: {n:,} splats: {step} reused ({lod if step == 'build' else scene})")
                save()
                continue
            log(f"scale-lod: {n:,} splats: {step} ...")
            try:
                row[step] = run_step(step, {**common, **extra}, cap)
            except StepFailed as exc:
                row[step] = {"failed": str(exc)}
                log(f"scale-lod: {n:,} splats: {step} failed: {exc}")
                save()
                if step in ("scene", "build"):
                    return
                continue
            r = row[step]
            log(f"scale-lod: {n:,} splats: {step} {r['seconds']:.2f} s ({r['wall_s']:.2f} s "
                f"from process start), peak {r['peak_rss_mb']:.0f} MB")
            if step == "build":   # the figures a later run reusing the files shows
                write_record(folder, n, row)
            if step == "full":
                for key, lod_image, full_image in (("psnr_view_db", "frame", "full"),
                                                   ("psnr_far_db", "far", "full far")):
                    if "seconds" in row.get(lod_image, {}):
                        row[key] = _psnr(images[lod_image], images[full_image])
                log(f"scale-lod: {n:,} splats: against full detail: default view "
                    f"{row.get('psnr_view_db') or 'inf'} dB, far view {row.get('psnr_far_db') or 'inf'} dB")
            save()
        if not fits:
            row["psnr_view_db"] = row["psnr_far_db"] = why
            save()
    finally:
        if not options.keep_scenes:
            kept = {scene} if found.scene else set()
            kept |= {lod, record_path(folder, n)} if found.lod else set()
            for p in {scene, lod, record_path(folder, n), *images.values()} - kept:
                p.unlink(missing_ok=True)


def run_scale_lod(options: ScaleLodOptions, out: Path | None, machine: dict, log=print) -> dict:
    """Measure every size; the report (also written to ``out``/scale-lod.json as it grows)."""
    from .scale_lod_report import plot, write_json

    missing = [n for n in REAL_SOURCES if not (shared_scenes_dir() / n).is_file()]
    if missing:
        raise SplatglError(f"--scale --lod: {shared_scenes_dir() / missing[0]}: shared real scene "
                           f"not found ({shared_scenes_help()})")
    made = options.scratch is None
    folder = Path(tempfile.mkdtemp(prefix="splatgl-scale-lod-")) if made else Path(options.scratch)
    if folder.exists() and not folder.is_dir():
        raise SplatglError(f"--scale --lod: scratch folder {folder}: not a folder")
    found = {} if made or not folder.is_dir() else {   # a stale file: one line, before any work
        n: find(folder, n, options.branching) for n in options.sizes}
    check_disk(folder, options.sizes, options.keep_scenes, found)
    folder.mkdir(parents=True, exist_ok=True)
    report = {"machine": machine, "options": {**asdict(options), "scratch": str(folder)},
              "rows": []}

    def save() -> None:
        if out is not None:
            write_json(out / "scale-lod.json", report)

    if out is not None:
        out.mkdir(parents=True, exist_ok=True)
    try:
        for n in options.sizes:
            row = {"splats": n}
            report["rows"].append(row)
            measure_size(n, options, folder, row, save, log, found.get(n, Found()))
            if out is not None:
                plot(out / "scale-lod.png", report["rows"], options.memory)
    finally:
        if made and not options.keep_scenes:
            shutil.rmtree(folder, ignore_errors=True)
        elif options.keep_scenes:
            log(f"scale-lod: scene files kept in {folder}")
    return report

