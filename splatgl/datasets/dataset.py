"""Evaluation datasets: cameras with their photographs, at the trainers' resolution, split.

- COLMAP datasets (Mip-NeRF 360, Tanks and Temples, ...): ``DIR/sparse/0`` (or ``DIR/sparse``)
  with the photographs in ``DIR/images`` (``images="images_4"`` picks a downscaled folder, as
  3DGS's ``-i images_4`` and gsplat's ``data_factor`` do).  Views sorted by image name.
- NeRF/nerfstudio datasets: ``DIR/transforms.json``, or ``transforms_train.json`` /
  ``transforms_test.json`` (Blender synthetic), photographs relative to the JSON file; with
  ``images="images_4"`` a ``file_path`` under ``images/`` is looked up under ``images_4/``.

Resolution: each camera's intrinsics are scaled to its photograph's actual size (so a
downscaled folder needs no other option); photographs wider than ``max_width`` (3DGS's rule:
1600) are downscaled to that width with the camera, unless ``max_width`` is 0.

Split (3DGS's ``--eval`` with ``llffhold = 8``): view i of the ordered list is a test view
when ``i % 8 == 0``, else a training view.  A Blender-style dataset's own
``transforms_test.json`` is its test split.
"""

from __future__ import annotations

import enum
from pathlib import Path

from ..errors import CameraError
from . import colmap, nerf
from .named_camera import NamedCamera

#: Every ``TEST_EVERY``-th view (from index 0) is a test view (3DGS's ``llffhold``).
TEST_EVERY = 8
#: 3DGS downscales photographs wider than this (its ``-r -1`` default).
MAX_WIDTH = 1600


class Split(enum.Enum):
    ALL = "all"
    TRAIN = "train"
    TEST = "test"


def split_views(views: list[NamedCamera], split: Split) -> list[NamedCamera]:
    split = Split(split)
    if split is Split.ALL:
        return list(views)
    test = split is Split.TEST
    return [v for i, v in enumerate(views) if (i % TEST_EVERY == 0) == test]


def _with_photo_size(view: NamedCamera, max_width: int) -> NamedCamera:
    """``view`` with its camera at its photograph's size; a photograph of another aspect (by
    more than a pixel's rounding) would stretch the render, so it is refused."""
    if view.image is None:
        return view
    w, h = nerf.image_size(view.image)
    cw, ch = view.camera.width, view.camera.height
    if abs(w * ch - h * cw) > max(cw, ch):   # |w - cw h / ch| > 1 and |h - ch w / cw| > 1
        raise CameraError(f"{view.image}: photograph {w}x{h} has another aspect than its camera's "
                          f"{cw}x{ch} ({w / h:.4g} against {cw / ch:.4g}); the render would be "
                          "stretched to it")
    if max_width and w > max_width:
        w, h = max_width, round(h * max_width / w)
    cam = view.camera
    if (w, h) != (cam.width, cam.height):
        cam = cam.resized(w, h)
    return NamedCamera(view.name, cam, view.image)


def _nerf_views(root: Path, images: str | None, split: Split) -> tuple[list[NamedCamera], bool]:
    """(views, already split) of a transforms.json dataset."""
    per_split = root / f"transforms_{split.value}.json"
    if split is not Split.ALL and per_split.is_file():
        path, done = per_split, True
    elif (root / "transforms.json").is_file():
        path, done = root / "transforms.json", False
    elif split is Split.ALL and (root / "transforms_train.json").is_file():
        views = []
        for part in ("train", "val", "test"):
            if (root / f"transforms_{part}.json").is_file():
                views += nerf.load_transforms(root / f"transforms_{part}.json")
        return _redirect(views, root, images), True
    else:
        raise CameraError(f"{root}: no transforms.json (or transforms_{split.value}.json)")
    return _redirect(nerf.load_transforms(path), root, images), done


def _redirect(views: list[NamedCamera], root: Path, images: str | None) -> list[NamedCamera]:
    if not images or images == "images":
        return views
    out = []
    for v in views:
        name = v.name[2:] if v.name.startswith("./") else v.name
        if not name.startswith("images/"):
            raise CameraError(f"{root}: frame {v.name!r} is not under images/, so --images {images} cannot apply")
        out.append(NamedCamera(v.name, v.camera, nerf.find_image(root, images + name[len("images"):])))
    return out


def load_dataset(root: str | Path, images: str | None = None, split: Split | str = Split.ALL,
                 max_width: int = MAX_WIDTH) -> list[NamedCamera]:
    """The views of the evaluation dataset in ``root`` with their photographs (see the module
    docstring); every view has an existing ``image``, else :class:`CameraError` names it."""
    root = Path(root)
    split = Split(split)
    if not root.is_dir():
        raise CameraError(f"{root}: no such dataset folder")
    model = colmap.find_model(root)
    if model is not None:
        folder = root / (images or "images")
        if not folder.is_dir():
            raise CameraError(f"{folder}: no such image folder beside the COLMAP model {model}")
        views, done = colmap.load_colmap(model, folder), False
        missing = next((v for v in views if v.image is None), None)
        if missing is not None:
            raise CameraError(f"{folder / missing.name}: photograph of COLMAP image {missing.name!r} not found")
    else:
        half = colmap.incomplete_model(root)
        if half is not None and not any(root.glob("transforms*.json")):
            raise CameraError(half)
        views, done = _nerf_views(root, images, split)
        missing = next((v for v in views if v.image is None), None)
        if missing is not None:
            raise CameraError(f"{root}: photograph of frame {missing.name!r} not found")
    if not done:
        views = split_views(views, split)
    if not views:
        raise CameraError(f"{root}: the {split.value} split holds no views")
    return [_with_photo_size(v, max_width) for v in views]
