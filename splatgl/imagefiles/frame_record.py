"""What made a frame of ``render --path``, recorded in the frame file itself, so that
``--resume`` keeps only frames of the same path, scene and render options.

Every frame file (PNG, TIFF, EXR; the frames a sharded video waits for too) carries in its
``ImageDescription`` header attribute a line ``splatgl frame {json}``: the ``--path`` it was
rendered for (as given, for messages) and digests of its camera (size, intrinsics, pose and
model), of the scene (its splats' values, after loading) and of the render options that decide
the pixels (settings, renderer, layers, bit depth, level-of-detail cut, stereo, preview), and
the renderer's name in plain text: ``--resume`` with ``--renderer auto`` draws the missing
frames with the renderer that drew those kept (:func:`recorded_renderer`).  The
record travels with the frame: written in the same atomic write, it can never describe another
file, and parts of one path rendered apart (``--select``, workers, Ray) agree.

``--resume`` reads it from each complete frame it would keep (:func:`kept_frame`): a frame of
another camera, scene or options stops the run before any work, in one line naming the frame
and the path it was rendered for.  A frame without a record (written by a splatgl from before
this record, or by another program) is kept, as resuming always did, and counted, so the run's
summary says how many such frames it could not check.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import SplatglError

#: The header attribute that holds the record (one every format OpenImageIO writes keeps).
ATTRIBUTE = "ImageDescription"
#: What the attribute's text starts with.
PREFIX = "splatgl frame "


def _digest(*parts) -> str:
    """A short hex digest of ``parts``: arrays by their dtype, shape and bytes, the rest by
    their canonical JSON (``repr`` for what JSON cannot say)."""
    h = hashlib.sha256()
    for part in parts:
        if isinstance(part, np.ndarray):
            h.update(f"{part.dtype.str}{part.shape}".encode())
            h.update(np.ascontiguousarray(part).tobytes())
        else:
            h.update(json.dumps(part, sort_keys=True, default=repr).encode())
        h.update(b"\0")
    return h.hexdigest()[:20]


def camera_digest(camera) -> str:
    """The digest of a :class:`~splatgl.cameras.camera.Camera`: size, intrinsics, pose, model."""
    return _digest([camera.width, camera.height, float(camera.fx), float(camera.fy),
                    float(camera.cx), float(camera.cy), repr(camera.model)],
                   np.asarray(camera.world_to_camera, np.float64))


def scene_digest(scene) -> str:
    """The digest of a :class:`~splatgl.scene.splats.Scene`'s splats (every value drawn)."""
    return _digest(str(scene.kind), *(np.asarray(getattr(scene, name)) for name in
                                      ("means", "quats", "log_scales", "opacity_logits", "sh")))


@dataclass(frozen=True)
class FrameRecord:
    """What a run's frames are rendered from, but the camera: ``source`` (the ``--path`` as
    given), and the ``scene`` and ``options`` digests (:func:`scene_digest`, and
    :func:`options_digest` of whatever else decides the pixels)."""

    source: str
    scene: str
    options: str
    #: The renderer that drew the frames, also in plain text (``--resume`` with ``--renderer
    #: auto`` takes it up: :func:`recorded_renderer`); None: not said (older records).
    renderer: str | None = None

    def text(self, camera) -> str:
        """The attribute text of the frame of ``camera``."""
        fields = {"path": self.source, "camera": camera_digest(camera), "scene": self.scene,
                  "options": self.options}
        if self.renderer is not None:
            fields["renderer"] = self.renderer
        return PREFIX + json.dumps(fields, sort_keys=True)

    def attributes(self, camera) -> dict[str, str]:
        """The header attributes of the frame of ``camera``."""
        return {ATTRIBUTE: self.text(camera)}


def options_digest(**options) -> str:
    """The digest of the render options (keyword values: settings, renderer, layers...)."""
    return _digest(options)


def read_record(description: str | None) -> dict | None:
    """The record in a frame's ``ImageDescription`` (None: the frame has none)."""
    if not description or not description.startswith(PREFIX):
        return None
    try:
        record = json.loads(description[len(PREFIX):])
    except ValueError:
        return None
    return record if isinstance(record, dict) else None


def recorded_renderer(paths) -> tuple[str, Path] | None:
    """The renderer the first complete frame among ``paths`` that records one was drawn by,
    and that frame (None: no such frame: none there yet, or only frames of older records)."""
    from .images import inspect_image

    for path in paths:
        if not Path(path).is_file():
            continue
        info = inspect_image(path)
        found = None if isinstance(info, str) else read_record(info.description)
        if found is not None and isinstance(found.get("renderer"), str):
            return found["renderer"], Path(path)
    return None


def kept_frame(path: Path, description: str | None, record: FrameRecord, camera) -> bool:
    """Whether the complete frame ``path`` (its header's ``description``) may be kept by a run
    of ``record`` drawing ``camera`` there: True when its record matches, False when it has
    none (kept, counted as unchecked); a record of another camera, scene or options is
    refused in one line."""
    found = read_record(description)
    if found is None:
        return False
    differ = [what for what, key, want in (("another camera", "camera", camera_digest(camera)),
                                           ("another scene", "scene", record.scene),
                                           ("other render options", "options", record.options))
              if found.get(key) != want]
    if differ:
        was = found.get("path")
        source = (f"for --path {was}, not this run's --path {record.source}"
                  if was != record.source else f"also for --path {was}")
        raise SplatglError(f"{path}: rendered with {' and '.join(differ)} ({source}); "
                           "--resume only completes frames of the same path, scene and options "
                           "(render into another folder, or replace them: --force without "
                           "--resume)")
    return True
