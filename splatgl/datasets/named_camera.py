"""What every camera loader returns: cameras with the name of the photograph they belong to."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from ..cameras.camera import Camera


@dataclass(frozen=True)
class NamedCamera:
    """One camera of a camera source.

    Attributes:
        name: the photograph's name as the source gives it (``"DSC0001.JPG"``,
            ``"./train/r_0"``), or ``"frame_00012"`` where the source has none (paths).
        camera: the camera, OpenCV axes, intrinsics at the source's own resolution.
        image: the photograph's file when the source names one that exists, else None.
    """

    name: str
    camera: Camera
    image: Path | None = None
