"""One entry point for every camera source, detected by content.

:func:`load_views` accepts:

- a COLMAP model folder (``cameras.bin``/``images.bin`` or ``.txt``), a dataset folder with
  ``sparse/0`` in it, or one of the model's files;
- a ``transforms.json`` (NeRF/nerfstudio), or a folder holding one;
- a 3DGS ``cameras.json`` (a JSON list), or a folder holding one (training output);
- a nerfstudio ``camera_path.json`` (an object with ``camera_path``);
- a splatgl path file (an object with ``splatgl_path``: keyframes, interpolated);
- a splatgl single-camera JSON (an object with ``world_to_camera``).
"""

from __future__ import annotations

from pathlib import Path

from ..cameras.camera import Camera
from ..cameras.camera_files import camera_from_json
from ..errors import CameraError
from . import colmap, gs_cameras, nerf, nerfstudio_path
from ..cameras.json_fields import read_json
from .named_camera import NamedCamera

_JSON_NAMES = ("transforms.json", "cameras.json", "camera_path.json")


def _from_json(path: Path) -> tuple[list[NamedCamera], float | None]:
    from ..paths.keyframes import is_path_file, parse_path

    obj = read_json(path)
    if isinstance(obj, list):
        return gs_cameras.load_gs_cameras(path, obj), None
    if nerf.is_transforms(obj):
        return nerf.load_transforms(path, obj), None
    if nerfstudio_path.is_camera_path(obj):
        return nerfstudio_path.load_camera_path(path, obj), nerfstudio_path.frame_rate(obj)
    if is_path_file(obj):
        parsed = parse_path(path, obj)
        fps = parsed.fps if parsed.fps is not None else nerfstudio_path.frame_rate(obj)
        return [NamedCamera(f"frame_{i:05d}", c) for i, c in enumerate(parsed.cameras())], fps
    if isinstance(obj, dict) and ("world_to_camera" in obj or "frustum" in obj):
        return [NamedCamera(path.stem, camera_from_json(obj, path))], None
    raise CameraError(f"{path}: not a camera source splatgl knows (expected a 3DGS cameras.json list, "
                      "a transforms.json with 'frames', a nerfstudio camera_path.json, a splatgl "
                      "path file with 'splatgl_path', or a single camera with 'world_to_camera')")


def load_source(path: str | Path) -> tuple[list[NamedCamera], float | None]:
    """(views, frame rate or None) of any camera source; see the module docstring."""
    path = Path(path)
    if not path.exists():
        raise CameraError(f"{path}: no such file or folder")
    if path.is_dir():
        model = colmap.find_model(path)
        if model is not None:
            images = path / "images" if (path / "images").is_dir() else None
            return colmap.load_colmap(model, images), None
        for name in _JSON_NAMES:
            if (path / name).is_file():
                return _from_json(path / name)
        half = colmap.incomplete_model(path)
        if half is not None:
            raise CameraError(half)
        raise CameraError(f"{path}: folder holds no camera source (looked for a COLMAP model in "
                          f"it or sparse/0, and for {', '.join(_JSON_NAMES)})")
    if path.suffix.lower() in (".bin", ".txt"):
        if colmap.is_colmap_model(path.parent):
            return colmap.load_colmap(path.parent), None
        raise CameraError(f"{path}: a .bin/.txt camera source must sit in a COLMAP model folder "
                          "beside cameras and images files")
    return _from_json(path)


def load_views(path: str | Path, select: str | None = None) -> list[NamedCamera]:
    """The views of any camera source, optionally narrowed by :func:`select_indices`."""
    views, _ = load_source(path)
    if select:
        views = [views[i] for i in select_indices(select, len(views), str(path))]
    return views


def load_cameras(path: str | Path, select: str | None = None) -> list[Camera]:
    """Every camera of a camera source (any format in the module docstring), in order.

    ``select`` narrows them: ``"0:100:5"`` (Python slice), ``"3"``, or a comma list of both.
    """
    return [v.camera for v in load_views(path, select)]


def select_indices(spec: str, count: int, what: str = "cameras") -> list[int]:
    """Indices picked by ``spec`` among ``count``: comma-separated ``i`` or ``start:stop[:step]``
    items (Python slice rules, negative indices count from the end).  An index, or a slice
    bound, beyond the cameras is refused (a slice is never clamped to them silently)."""
    out: list[int] = []
    for item in spec.split(","):
        item = item.strip()
        try:
            parts = [int(p) if p.strip() else None for p in item.split(":")]
        except ValueError:
            parts = []
        if not 1 <= len(parts) <= 3 or (len(parts) == 3 and parts[2] == 0) or (len(parts) == 1 and parts[0] is None):
            raise CameraError(f"{what}: --select item {item!r} is not an index or start:stop:step")
        if len(parts) > 1:
            for name, bound in zip(("start", "stop"), parts[:2]):
                if bound is not None and not -count <= bound <= count:
                    raise CameraError(f"{what}: --select {item!r}: {name} {bound} out of range "
                                      f"({count} cameras)")
            out.extend(range(count)[slice(*parts)])
            continue
        i = parts[0]
        if not -count <= i < count:
            raise CameraError(f"{what}: --select index {i} out of range ({count} cameras)")
        out.append(i % count)
    if not out:
        raise CameraError(f"{what}: --select {spec!r} picks no camera of {count}")
    return out
