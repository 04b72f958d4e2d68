"""H.264 video output through PyAV (FFmpeg's libraries, shipped inside the wheel: no system
ffmpeg needed).  PyAV is the optional ``video`` extra: ``pip install 'splatgl[video]'``.

The video is written to a hidden temporary file beside the target and renamed into place only
when complete; if writing stops early (an error, Ctrl-C, SIGTERM) the temporary file is
removed, so the target is either a complete, playable video or absent.
"""

from __future__ import annotations

import os
from fractions import Fraction
from pathlib import Path

import numpy as np

from .errors import SplatglError

VIDEO_SUFFIXES = (".mp4", ".mov", ".mkv")
#: x264 constant rate factor: 18 is visually near-lossless for rendered frames.
DEFAULT_CRF = 18


def _import_av():
    try:
        import av
    except ImportError:
        raise SplatglError("video output needs PyAV: pip install 'splatgl[video]' (or pip install av)") from None
    return av


def check_video_size(path: Path, width: int, height: int) -> None:
    """H.264 in yuv420p (what players accept) needs even sizes."""
    if width % 2 or height % 2:
        raise SplatglError(f"{path}: H.264 video needs an even width and height, got {width}x{height} "
                           "(pass --width/--height)")


class VideoWriter:
    """Write (H, W, 4) float32 frames (RGB used, background already composited) to a video.

    Use as a context manager: leaving normally finishes and renames the file; leaving by an
    exception removes the partial file.
    """

    def __init__(self, path: str | Path, width: int, height: int, fps: float = 30.0,
                 crf: int = DEFAULT_CRF):
        av = _import_av()
        self.path = Path(path)
        if self.path.suffix.lower() not in VIDEO_SUFFIXES:
            raise SplatglError(f"{self.path}: video output must end in {', '.join(VIDEO_SUFFIXES)}")
        check_video_size(self.path, width, height)
        if not fps > 0:
            raise SplatglError(f"video frame rate must be positive, got {fps}")
        self.width, self.height = width, height
        self.tmp = self.path.with_name(f".{self.path.stem}.partial{os.getpid()}{self.path.suffix}")
        self.frames = 0
        self._container = av.open(str(self.tmp), mode="w")
        try:
            rate = Fraction(fps).limit_denominator(1001)
            self._stream = self._container.add_stream("libx264", rate=rate)
            self._stream.width, self._stream.height = width, height
            self._stream.pix_fmt = "yuv420p"
            self._stream.options = {"crf": str(crf), "preset": "medium"}
        except BaseException:
            self.abort()
            raise
        self._av = av

    def write(self, rgba: np.ndarray) -> None:
        if rgba.shape[:2] != (self.height, self.width):
            raise SplatglError(f"{self.path}: every video frame must be {self.width}x{self.height}, "
                               f"got {rgba.shape[1]}x{rgba.shape[0]}")
        rgb = np.ascontiguousarray((np.clip(rgba[..., :3], 0.0, 1.0) * 255.0 + 0.5).astype(np.uint8))
        frame = self._av.VideoFrame.from_ndarray(rgb, format="rgb24").reformat(format="yuv420p")
        for packet in self._stream.encode(frame):
            self._container.mux(packet)
        self.frames += 1

    def close(self) -> None:
        """Flush the encoder, finish the file and rename it into place."""
        try:
            for packet in self._stream.encode(None):
                self._container.mux(packet)
            self._container.close()
        except BaseException:
            self.abort()
            raise
        self.tmp.replace(self.path)

    def abort(self) -> None:
        """Stop without a video: close and delete the temporary file."""
        try:
            self._container.close()
        except Exception:  # noqa: BLE001 - the file is deleted anyway
            pass
        if self.tmp.exists():
            self.tmp.unlink()

    def __enter__(self) -> "VideoWriter":
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        if exc_type is None:
            self.close()
        else:
            self.abort()


def read_video_frames(path: str | Path) -> list[np.ndarray]:
    """Decode every frame as (H, W, 3) uint8 RGB (tests, checks)."""
    av = _import_av()
    with av.open(str(path)) as container:
        return [f.to_ndarray(format="rgb24") for f in container.decode(video=0)]
