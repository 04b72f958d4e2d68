"""Where a batch of frames goes: a folder, a printf pattern, or a video file.

- ``frames/`` (an existing folder, or a name without an image/video suffix): files
  ``frames/00000.png``, ``00001.png``, ... (``image_format`` picks png, tif or exr);
- ``frames/%05d.exr``: a printf pattern with one integer field (the frame index);
- ``flythrough.mp4`` (``.mov``, ``.mkv``): an H.264 video (:mod:`splatgl.video`).
"""

from __future__ import annotations

import enum
from dataclasses import dataclass
from pathlib import Path

from .errors import SplatglError
from .video import VIDEO_SUFFIXES

IMAGE_SUFFIXES = (".png", ".tif", ".tiff", ".exr")
DEFAULT_PATTERN = "%05d"


class TargetKind(enum.Enum):
    IMAGES = "images"
    VIDEO = "video"


@dataclass(frozen=True)
class FrameTarget:
    """A parsed output: ``pattern`` (a printf pattern of image paths) or a ``video`` path."""

    kind: TargetKind
    pattern: str | None = None
    video: Path | None = None

    @classmethod
    def parse(cls, out: str | Path, image_format: str | None = None) -> "FrameTarget":
        """``out`` parsed; ``image_format`` (``--format``; default png) applies to a folder only
        (a video or a pattern's suffix says what it holds), elsewhere it is refused."""
        text = str(out)
        suffix = Path(text).suffix.lower()
        if image_format is not None and (suffix in VIDEO_SUFFIXES or "%" in text):
            what = "a video" if suffix in VIDEO_SUFFIXES else "a pattern whose suffix names the image type"
            raise SplatglError(f"--format {image_format}: -o {text} is {what}; --format picks the "
                               "image type of frames written into a folder")
        image_format = image_format or "png"
        if suffix in VIDEO_SUFFIXES:
            if "%" in text:
                raise SplatglError(f"{text}: a video file name takes no printf pattern")
            return cls(TargetKind.VIDEO, video=Path(text))
        if "%" in text:
            if suffix not in IMAGE_SUFFIXES:
                raise SplatglError(f"{text}: a frame pattern must end in {', '.join(IMAGE_SUFFIXES)}")
            try:
                a, b = text % 0, text % 1
            except (TypeError, ValueError):
                raise SplatglError(f"{text}: a frame pattern needs exactly one integer field such as %05d") from None
            if a == b:
                raise SplatglError(f"{text}: the pattern's field does not change with the frame index")
            return cls(TargetKind.IMAGES, pattern=text)
        if suffix in IMAGE_SUFFIXES and not Path(text).is_dir():
            raise SplatglError(f"{text}: many frames need a folder or a pattern such as "
                               f"{Path(text).with_name(Path(text).stem + '_%05d' + suffix)}")
        fmt = image_format.lower().lstrip(".")
        if "." + fmt not in IMAGE_SUFFIXES:
            raise SplatglError(f"--format must be one of png, tif, exr; got {image_format!r}")
        return cls(TargetKind.IMAGES, pattern=str(Path(text) / f"{DEFAULT_PATTERN}.{fmt}"))

    @property
    def is_video(self) -> bool:
        return self.kind is TargetKind.VIDEO

    @property
    def wants_depth(self) -> bool:
        """EXR frames carry the depth channel, as ``splatgl render -o x.exr`` does."""
        return not self.is_video and self.pattern.lower().endswith(".exr")

    def frame_path(self, index: int) -> Path:
        return Path(self.pattern % index)

    def prepare(self) -> None:
        """Create the folder the frames or the video go into."""
        parent = self.video.parent if self.is_video else self.frame_path(0).parent
        try:
            parent.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise SplatglError(f"{parent}: cannot create the output folder ({exc.strerror})") from None
