"""Where a batch of frames goes: a folder, a printf pattern, or a video file.

- ``frames/`` (an existing folder, a name without a suffix, or one ending in ``/``): files
  ``frames/00000.png``, ``00001.png``, ... (``image_format`` picks png, tif or exr);
- ``frames/%05d.exr``: a printf pattern with one integer field (the frame index);
- ``flythrough.mp4`` (``.mov``, ``.mkv``): an H.264 video (:mod:`splatgl.imagefiles.video`).

Any other suffix (``f.avi``, ``f.gif``, ``f.jpg``) is refused, never taken for a folder.
"""

from __future__ import annotations

import dataclasses
import enum
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

from ..errors import SplatglError
from ..writing.outputs import folder_writable
from ..output.layers import BASE, Layer, NormalSpace
from .image_formats import (DEFAULT_FORMAT, FORMAT_NAMES, IMAGE_SUFFIXES, ImageFormat, find_format,
                            format_named)
from .images import inspect_image
from .frame_record import FrameRecord, kept_frame
from .layer_files import LayerFiles
from ..output.under import DepthKind
from .video import VIDEO_SUFFIXES

DEFAULT_PATTERN = "%05d"


class TargetKind(enum.Enum):
    IMAGES = "images"
    VIDEO = "video"


@dataclass(frozen=True)
class FrameTarget:
    """A parsed output: ``pattern`` (a printf pattern of image paths) or a ``video`` path, and
    the layers each frame holds (``named``, ``--layers``; empty: the format's own, and
    ``normal_space``; :meth:`with_layers`)."""

    kind: TargetKind
    pattern: str | None = None
    video: Path | None = None
    named: tuple[Layer, ...] = ()
    normal_space: NormalSpace = NormalSpace.CAMERA

    def with_layers(self, named: tuple[Layer, ...],
                    normal_space: NormalSpace = NormalSpace.CAMERA) -> "FrameTarget":
        """This target with ``--layers``; a video, which holds colour alone, refuses others."""
        if self.is_video and set(named) - {Layer.COLOUR}:
            raise SplatglError(f"{self.video}: a video holds the colour alone; write frames "
                               "(-o frames/%05d.exr, or .png for a picture per layer) for --layers")
        return dataclasses.replace(self, named=tuple(named), normal_space=NormalSpace(normal_space))

    def files(self, camera=None) -> LayerFiles:
        """How a frame of ``camera`` (a :class:`~splatgl.cameras.camera.Camera`: its pose for
        world normals, its model's depth metric) writes its layers."""
        world = self.normal_space is NormalSpace.WORLD and camera is not None
        lens = camera is not None and camera.model.depth_is_distance
        return LayerFiles(self.named, self.normal_space,
                          camera.world_to_camera if world else None,
                          DepthKind.DISTANCE if lens else DepthKind.Z)

    def frame_paths(self, index: int) -> list[Path]:
        """Every file of frame ``index``: the image and its layer pictures."""
        return self.files().paths(self.frame_path(index))

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
        image_format = image_format or DEFAULT_FORMAT.name
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
        folder = Path(text).is_dir() or text.endswith(("/", os.sep))
        if suffix in IMAGE_SUFFIXES and not folder:
            raise SplatglError(f"{text}: many frames need a folder or a pattern such as "
                               f"{Path(text).with_name(Path(text).stem + '_%05d' + suffix)}")
        if suffix and not folder:  # f.avi, f.gif, f.jpg: never a folder of PNGs named so
            raise SplatglError(
                f"{text}: unknown output type '{suffix}'; give a video ({', '.join(VIDEO_SUFFIXES)}), "
                f"a frame pattern such as {Path(text).stem}_%05d.png ({', '.join(IMAGE_SUFFIXES)}) "
                "or a folder (a name without a suffix, or ending in /)")
        if format_named(image_format) is None:
            raise SplatglError(f"--format must be one of {', '.join(FORMAT_NAMES)}; got {image_format!r}")
        suffix = "." + image_format.lower().lstrip(".")  # as given: tif or tiff
        return cls(TargetKind.IMAGES, pattern=str(Path(text) / f"{DEFAULT_PATTERN}{suffix}"))

    @property
    def is_video(self) -> bool:
        return self.kind is TargetKind.VIDEO

    @property
    def image_format(self) -> ImageFormat | None:
        """The format of the frame files (None: a video)."""
        return None if self.is_video else find_format(self.pattern)

    @property
    def layers(self) -> frozenset[Layer] | None:
        """The layers each frame needs beyond colour and alpha (None: those alone): the ones
        named, else what the frames' format holds
        (:attr:`~splatgl.imagefiles.image_formats.ImageFormat.render_layers`; EXR frames carry the
        depth channel, as ``splatgl render -o x.exr`` does)."""
        fmt = self.image_format
        if fmt is None:
            return None
        layers = self.files().render_layers(self.frame_path(0))
        return layers if layers != BASE else None

    def frame_path(self, index: int) -> Path:
        return Path(self.pattern % index)

    def prepare(self) -> None:
        """Create the folder the frames or the video go into; refuse one that is not writable
        (before any frame renders)."""
        parent = self.video.parent if self.is_video else self.frame_path(0).parent
        try:
            parent.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise SplatglError(f"{parent}: cannot create the output folder ({exc.strerror})") from None
        if not folder_writable(parent):
            raise SplatglError(f"{parent}: the output folder is not writable")


@dataclass(frozen=True)
class FramePlan:
    """Which frames a run renders: ``todo`` (indices into its cameras), how many complete
    frames it keeps (``skipped``), how many damaged ones it renders again (``damaged``) and
    how many of those kept carry no record of what made them (``unchecked``: written before
    splatgl recorded it, or by another program; :mod:`splatgl.imagefiles.frame_record`)."""

    todo: list[int]
    skipped: int = 0
    damaged: int = 0
    unchecked: int = 0


def plan_frames(target: FrameTarget, sizes: Sequence[tuple[int, int]], numbers: Sequence[int],
                bit_depth: int = 8, resume: bool = False, record: FrameRecord | None = None,
                cameras: Sequence | None = None) -> FramePlan:
    """The frames to render of cameras whose frames are ``sizes`` (width, height) numbered
    ``numbers``.  Without ``resume`` (or into a video): all of them.  With ``resume`` a frame
    file that exists is kept only when it is complete (:func:`splatgl.imagefiles.images.inspect_image`:
    a file cut short by a full disk or a killed run is rendered again); a complete frame of
    another size, channel count or bit depth stops the run before any work, in one line, and
    so does, given the run's ``record`` and ``cameras``, one recorded as rendered from another
    camera, scene or options (:func:`splatgl.imagefiles.frame_record.kept_frame`)."""
    if not resume or target.is_video:
        return FramePlan(list(range(len(sizes))))
    fmt = target.image_format
    channels = len(fmt.channels(target.layers or BASE))
    todo, damaged, unchecked = [], 0, 0
    for k, ((width, height), number) in enumerate(zip(sizes, numbers)):
        path = target.frame_path(number)
        paths = target.frame_paths(number)
        if not all(p.exists() for p in paths):
            todo.append(k)
            continue
        info = inspect_image(path)
        if isinstance(info, str) or any(isinstance(inspect_image(p), str) for p in paths[1:]):
            todo.append(k)
            damaged += 1
            continue
        mismatch = info.mismatch(width, height, channels, bit_depth)
        if mismatch is not None:
            raise SplatglError(f"{path}: {mismatch} as this run renders its frames; --resume only "
                               "completes frames of the same kind (render into another folder, "
                               "or with --force instead of --resume to replace them)")
        if record is not None and not kept_frame(path, info.description, record, cameras[k]):
            unchecked += 1
    return FramePlan(todo, len(sizes) - len(todo), damaged, unchecked)
