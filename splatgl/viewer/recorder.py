"""K: the camera's flight recorded as a splatgl path file, the one ``splatgl render --path`` takes.

While recording, each loop iteration adds the camera as a timed keyframe (at most
:data:`RECORD_HZ` a second; the loop steps a few times a second at rest too, so rests stay
rests); K again writes ``splatgl-view-path-NNNN.json`` beside the screenshots (atomically: a
whole file or none), sampled at :data:`FPS` frames a second over the recorded time (the first
and last frames are the cameras K was pressed at), and prints
the command that renders it.  The format is :mod:`splatgl.paths.keyframes`'s: one
``world_to_camera`` and vertical ``fov`` per key, with its ``time``; in a lens view
(``view --projection``: fisheye, panorama, orthographic) the file's ``projection`` (and
``projection_fov``) name the model the viewer shows the keys' cameras through, so ``render
--path`` draws the lens view without options.
"""

from __future__ import annotations

import shlex
import time
from pathlib import Path

import numpy as np

from ..cameras.camera import Camera
from ..paths.keyframes import FORMAT_KEY, FORMAT_VERSION, write_path

#: Most keyframes recorded a second.
RECORD_HZ = 10.0
#: Frames a second of the path written (``render --path`` renders that many per recorded second).
FPS = 30.0
PREFIX = "splatgl-view-path-"


def next_path(directory: Path) -> Path:
    """The first unused ``splatgl-view-path-NNNN.json`` in ``directory``."""
    directory.mkdir(parents=True, exist_ok=True)
    n = 1
    while (directory / f"{PREFIX}{n:04d}.json").exists():
        n += 1
    return directory / f"{PREFIX}{n:04d}.json"


def path_object(keys: list[tuple[float, Camera]], fps: float = FPS,
                projection: str | None = None, projection_fov: float | None = None) -> dict:
    """The path file object of timed perspective cameras ``keys`` ((seconds from the start,
    camera), the times increasing), at the size of the last camera: ``fps`` frames a second
    over the span, the first and last frames on the first and last keys (the video's rate is
    ``fps``); ``projection`` (and its ``projection_fov``): the model the frames are seen
    through, as the viewer's ``--projection`` (:mod:`splatgl.paths.keyframes`)."""
    last = keys[-1][1]
    frames = max(2, int(round((keys[-1][0] - keys[0][0]) * fps)) + 1)
    obj = {FORMAT_KEY: FORMAT_VERSION, "width": last.width, "height": last.height,
           "frames": frames, "fps": fps}
    if projection is not None:
        obj["projection"] = projection
        if projection_fov is not None:
            obj["projection_fov"] = float(projection_fov)
    obj["keyframes"] = [{"world_to_camera": c.world_to_camera.tolist(),
                         "fov": float(np.degrees(2.0 * np.arctan(0.5 * c.height / c.fy))),
                         "time": t} for t, c in keys]
    return obj


class Recorder:
    """The keyframes of a recording in progress (none: not recording)."""

    def __init__(self) -> None:
        self.keys: list[tuple[float, Camera]] | None = None
        self._start = 0.0

    @property
    def recording(self) -> bool:
        return self.keys is not None

    def start(self, camera: Camera, now: float | None = None) -> None:
        self._start = time.perf_counter() if now is None else now
        self.keys = [(0.0, camera)]

    def add(self, camera: Camera, now: float | None = None, force: bool = False) -> None:
        """Record ``camera`` at ``now`` (a :func:`time.perf_counter` reading), unless the last
        key is under 1 / :data:`RECORD_HZ` seconds old (``force``: unless it is as old)."""
        if self.keys is None:
            return
        t = (time.perf_counter() if now is None else now) - self._start
        gap = t - self.keys[-1][0]
        if gap > 0.0 and (force or gap >= 1.0 / RECORD_HZ):
            self.keys.append((t, camera))

    def stop(self, directory: Path, camera: Camera, now: float | None = None,
             projection: str | None = None, projection_fov: float | None = None) -> Path | None:
        """End the recording with ``camera``; write the path file into ``directory`` and return
        it, or None where the recording is shorter than one frame of the path.  ``projection``,
        ``projection_fov``: the lens the cameras were shown through (:func:`path_object`)."""
        self.add(camera, now, force=True)
        keys, self.keys = self.keys or [], None
        if len(keys) < 2 or keys[-1][0] * FPS < 1.0:
            return None
        out = next_path(Path(directory))
        write_path(out, path_object(keys, FPS, projection, projection_fov))
        return out


def toggle(viewer) -> str:
    """K in ``viewer`` (:class:`~.app.Viewer`): start recording, or stop and write the path file;
    returns the status message (the command that renders the path is printed)."""
    v, rec = viewer, viewer.recorder
    camera = v.nav.camera(max(v.size[0], 1), max(v.size[1], 1))
    if not rec.recording:
        rec.start(camera)
        return "recording the camera path (K stops and writes it)"
    out = rec.stop(v.options.screenshot_dir, camera, projection=v.options.projection,
                   projection_fov=v.options.fisheye_fov)
    if out is None:
        return "path not written: recorded for less than one frame"
    from .screenshot import settings_arguments

    argv = ["splatgl", "render", *v.options.render_args, "--path", str(out),
            *settings_arguments(v.settings, v.kind), "-o", str(out.with_suffix(""))]
    print(f"wrote {out}; render it with:\n  {shlex.join(argv)}", flush=True)
    return f"saved {out.name} (splatgl render --path)"
