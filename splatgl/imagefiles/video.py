"""H.264 video output through PyAV (FFmpeg's libraries, shipped inside the wheel: no system
ffmpeg needed).  PyAV is the optional ``video`` extra: ``pip install 'splatgl[video]'``.

The video is written to a hidden temporary file beside the target, read back (every frame's
packet must be there) and renamed into place only when complete; if writing stops early (an
error such as a full disk, Ctrl-C, SIGTERM) the temporary file is removed, so the target is
either a complete, playable video or absent, and a failed write is one line naming the target.
"""

from __future__ import annotations

from contextlib import contextmanager
from fractions import Fraction
from pathlib import Path

import numpy as np

from ..writing.atomic import AtomicTarget, write_error
from ..errors import SplatglError

VIDEO_SUFFIXES = (".mp4", ".mov", ".mkv")
#: x264 constant rate factor: 18 is visually near-lossless for rendered frames.
DEFAULT_CRF = 18

#: x264's names for the x86 instruction sets below AVX-512, each with the /proc/cpuinfo flag
#: that shows it (x264 accepts a list of these names as its ``asm`` parameter).
_X264_BELOW_AVX512 = (("mmxext", "MMX2"), ("sse", "SSE"), ("sse2", "SSE2"), ("pni", "SSE3"),
                      ("ssse3", "SSSE3"), ("sse4_1", "SSE4.1"), ("sse4_2", "SSE4.2"),
                      ("avx", "AVX"), ("xop", "XOP"), ("fma4", "FMA4"), ("fma", "FMA3"),
                      ("bmi1", "BMI1"), ("bmi2", "BMI2"), ("avx2", "AVX2"), ("abm", "LZCNT"))


def x264_asm(cpuinfo_text: str | None = None) -> str | None:
    """x264's ``asm`` parameter that keeps it off its AVX-512 code, or None to leave its own
    detection alone (no AVX-512, or not an x86 Linux machine).

    Why: on CPUs with AVX-512, the x264 inside PyAV's wheels gave different bitstreams for the
    same frames from run to run (decoded frames off by up to 16 levels), depending on what the
    process had allocated and freed before: its AVX-512 paths read memory that the encoder
    never wrote.  Capped at AVX2 the same frames encoded to the same bytes every time (40 of
    40 runs with the heap churned between them; uncapped 7 of 10), at 0.91x the encoding speed
    (720p, medium preset); encoding runs beside rendering on the writer thread.
    """
    if cpuinfo_text is None:
        try:
            cpuinfo_text = Path("/proc/cpuinfo").read_text(errors="replace")
        except OSError:
            return None
    flags: set[str] = set()
    for line in cpuinfo_text.splitlines():
        key, _, value = line.partition(":")
        if key.strip().lower() == "flags":
            flags = set(value.split())
            break
    if "avx512f" not in flags:
        return None
    if "sse" in flags:  # every SSE CPU has the MMX extensions x264 calls MMX2
        flags.add("mmxext")
    if "lzcnt" in flags:
        flags.add("abm")
    return ",".join(name for flag, name in _X264_BELOW_AVX512 if flag in flags)


def x264_options(crf: int = DEFAULT_CRF) -> dict[str, str]:
    """The encoder options every splatgl video uses: the same frames give the same file."""
    options = {"crf": str(crf), "preset": "medium"}
    asm = x264_asm()
    if asm:
        options["x264-params"] = f"asm={asm}"
    return options


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
        self.path = Path(path)
        if self.path.suffix.lower() not in VIDEO_SUFFIXES:
            raise SplatglError(f"{self.path}: video output must end in {', '.join(VIDEO_SUFFIXES)}")
        check_video_size(self.path, width, height)
        if not fps > 0:
            raise SplatglError(f"video frame rate must be positive, got {fps}")
        av = _import_av()       # after the checks: their errors hold with PyAV too
        self.width, self.height = width, height
        self.frames = 0
        self._file = AtomicTarget(self.path, lambda tmp: video_problem(tmp, self.frames))
        self.tmp = self._file.tmp
        self._container = None
        with self._or_abort():
            self._container = av.open(str(self.tmp), mode="w")
            rate = Fraction(fps).limit_denominator(1001)
            self._stream = self._container.add_stream("libx264", rate=rate)
            self._stream.width, self._stream.height = width, height
            self._stream.pix_fmt = "yuv420p"
            self._stream.options = x264_options(crf)
        self._av = av

    @contextmanager
    def _or_abort(self):
        """Whatever stops the block stops the video (:meth:`abort`); a failed write (a full disk)
        is said as the target's write error."""
        try:
            yield
        except OSError as exc:
            self.abort()
            raise write_error(self.path, exc) from None
        except BaseException:
            self.abort()
            raise

    def write(self, rgba: np.ndarray) -> None:
        if rgba.shape[:2] != (self.height, self.width):
            raise SplatglError(f"{self.path}: every video frame must be {self.width}x{self.height}, "
                               f"got {rgba.shape[1]}x{rgba.shape[0]}")
        rgb = np.ascontiguousarray((np.clip(rgba[..., :3], 0.0, 1.0) * 255.0 + 0.5).astype(np.uint8))
        frame = self._av.VideoFrame.from_ndarray(rgb, format="rgb24").reformat(format="yuv420p")
        try:
            for packet in self._stream.encode(frame):
                self._container.mux(packet)
        except OSError as exc:  # a full disk: the target is named, the temporary goes
            self.abort()
            raise write_error(self.path, exc) from None
        self.frames += 1

    def close(self) -> None:
        """Flush the encoder, finish the file, check it (:func:`video_problem`) and rename it
        into place."""
        with self._or_abort():
            for packet in self._stream.encode(None):
                self._container.mux(packet)
            self._container.close()
            self._file.commit()

    def abort(self) -> None:
        """Stop without a video: close and delete the temporary file."""
        try:
            if self._container is not None:
                self._container.close()
        except Exception:  # noqa: BLE001 - the file is deleted anyway
            pass
        self._file.discard()

    def __enter__(self) -> "VideoWriter":
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        if exc_type is None:
            self.close()
        else:
            self.abort()


def video_problem(path: str | Path, frames: int) -> str | None:
    """Why the video file ``path`` does not hold ``frames`` frames (None when it does): its
    container is read back and the packets of its video stream counted, without decoding."""
    av = _import_av()
    try:
        with av.open(str(path)) as container:
            count = sum(1 for packet in container.demux(video=0) if packet.size)
    except (OSError, av.error.FFmpegError) as exc:
        return f"the file cannot be read back ({' '.join(str(exc).split())})"
    return None if count == frames else f"the file holds {count} of {frames} frames"


def read_video_frames(path: str | Path) -> list[np.ndarray]:
    """Decode every frame as (H, W, 3) uint8 RGB (tests, checks)."""
    av = _import_av()
    with av.open(str(path)) as container:
        return [f.to_ndarray(format="rgb24") for f in container.decode(video=0)]
