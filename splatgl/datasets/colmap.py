"""COLMAP sparse models: ``cameras.bin``/``images.bin`` or ``cameras.txt``/``images.txt``.

Axes: COLMAP stores world-to-camera poses in OpenCV axes (+x right, +y down, +z forward) as a
unit quaternion ``(qw, qx, qy, qz)`` and translation ``t``: ``p_cam = R(q) p_world + t``;
the pixel centre of the top-left pixel is (0.5, 0.5), splatgl's convention too.  Which camera
models are read, and how, is the camera models' own table
(:data:`splatgl.cameras.registry.COLMAP`: each model's ``colmap_names`` and ``from_colmap``;
the pinhole's PINHOLE and SIMPLE_PINHOLE, the fisheye's OPENCV_FISHEYE, RADIAL_FISHEYE and
SIMPLE_RADIAL_FISHEYE, ...).  Any other model is rejected by name (undistort with
``colmap image_undistorter`` first, as 3DGS training does).  Writing uses each model's
``to_colmap``.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..cameras.camera import Camera
from ..cameras.poses import check_rigid_pose
from ..cameras.registry import COLMAP
from ..scene.quaternion import quat_to_rotmat, rotmat_to_quat
from ..errors import CameraError
from .named_camera import NamedCamera

#: COLMAP's camera model ids and their parameter counts (colmap/src/colmap/sensor/models.h).
MODELS = {
    0: ("SIMPLE_PINHOLE", 3), 1: ("PINHOLE", 4), 2: ("SIMPLE_RADIAL", 4), 3: ("RADIAL", 5),
    4: ("OPENCV", 8), 5: ("OPENCV_FISHEYE", 8), 6: ("FULL_OPENCV", 12), 7: ("FOV", 5),
    8: ("SIMPLE_RADIAL_FISHEYE", 4), 9: ("RADIAL_FISHEYE", 5), 10: ("THIN_PRISM_FISHEYE", 12),
    11: ("RAD_TAN_THIN_PRISM_FISHEYE", 16),
}
_BY_NAME = {name: (mid, n) for mid, (name, n) in MODELS.items()}


@dataclass(frozen=True)
class _Intrinsics:
    model: str
    width: int
    height: int
    params: tuple[float, ...]


class _Reader:
    """Little-endian binary reader with errors naming the file."""

    def __init__(self, path: Path):
        self.path, self.data, self.pos = path, path.read_bytes(), 0

    def read(self, fmt: str):
        size = struct.calcsize("<" + fmt)
        if self.pos + size > len(self.data):
            raise CameraError(f"{self.path}: truncated at byte {self.pos} (file has {len(self.data)})")
        out = struct.unpack_from("<" + fmt, self.data, self.pos)
        self.pos += size
        return out

    def name(self) -> str:
        end = self.data.find(b"\0", self.pos)
        if end < 0:
            raise CameraError(f"{self.path}: truncated image name at byte {self.pos}")
        raw, self.pos = self.data[self.pos:end], end + 1
        return raw.decode("utf-8", errors="replace")


def _read_cameras_bin(path: Path) -> dict[int, _Intrinsics]:
    r = _Reader(path)
    (count,) = r.read("Q")
    cams = {}
    for _ in range(count):
        cam_id, model_id, w, h = r.read("iiQQ")
        if model_id not in MODELS:
            raise CameraError(f"{path}: camera {cam_id}: unknown COLMAP model id {model_id}")
        name, n = MODELS[model_id]
        cams[cam_id] = _Intrinsics(name, int(w), int(h), r.read("d" * n))
    return cams


def _read_images_bin(path: Path) -> list[tuple[str, np.ndarray, np.ndarray, int]]:
    r = _Reader(path)
    (count,) = r.read("Q")
    images = []
    for _ in range(count):
        (_image_id, *rest) = r.read("idddddddi")
        q, t, cam_id = np.array(rest[:4]), np.array(rest[4:7]), rest[7]
        name = r.name()
        (n_points,) = r.read("Q")
        r.pos += n_points * struct.calcsize("<ddq")  # 2D points: not needed for rendering
        if r.pos > len(r.data):
            raise CameraError(f"{path}: truncated in the points of image {name!r}")
        images.append((name, q, t, cam_id))
    return images


def _text_lines(path: Path) -> list[tuple[int, str]]:
    try:
        text = path.read_text()
    except UnicodeDecodeError as exc:
        raise CameraError(f"{path}: not a text file ({exc.reason})") from None
    return [(i + 1, line) for i, line in enumerate(text.splitlines())
            if line.strip() and not line.lstrip().startswith("#")]


def _floats(path: Path, lineno: int, parts: list[str]) -> list[float]:
    try:
        return [float(p) for p in parts]
    except ValueError:
        raise CameraError(f"{path}: line {lineno}: expected numbers, got {' '.join(parts)!r}") from None


def _read_cameras_txt(path: Path) -> dict[int, _Intrinsics]:
    cams = {}
    for lineno, line in _text_lines(path):
        parts = line.split()
        if len(parts) < 4:
            raise CameraError(f"{path}: line {lineno}: expected CAMERA_ID MODEL WIDTH HEIGHT PARAMS...")
        model = parts[1]
        if model not in _BY_NAME:
            raise CameraError(f"{path}: line {lineno}: unknown COLMAP camera model {model!r}")
        nums = _floats(path, lineno, [parts[0], *parts[2:]])
        if len(nums) - 3 != _BY_NAME[model][1]:
            raise CameraError(f"{path}: line {lineno}: model {model} takes {_BY_NAME[model][1]} "
                              f"parameters, got {len(nums) - 3}")
        cams[int(nums[0])] = _Intrinsics(model, int(nums[1]), int(nums[2]), tuple(nums[3:]))
    return cams


def _read_images_txt(path: Path) -> list[tuple[str, np.ndarray, np.ndarray, int]]:
    # Two lines per image; the second (2D points) may be empty, which _text_lines would drop,
    # so walk the raw lines after the comments.
    raw = path.read_text().splitlines()
    lines = [(i + 1, l) for i, l in enumerate(raw) if not l.lstrip().startswith("#")]
    images = []
    k = 0
    while k < len(lines):
        lineno, line = lines[k]
        if not line.strip():
            k += 1
            continue
        parts = line.split()
        if len(parts) < 10:
            raise CameraError(f"{path}: line {lineno}: expected IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID NAME")
        nums = _floats(path, lineno, parts[1:9])
        images.append((" ".join(parts[9:]), np.array(nums[:4]), np.array(nums[4:7]), int(nums[7])))
        k += 2  # skip the POINTS2D line
    return images


def _intrinsics(path: Path, cam_id: int, cam: _Intrinsics) -> dict:
    """Camera keyword arguments (fx, fy, cx, cy, model) from the model that reads ``cam.model``."""
    model = COLMAP.get(cam.model)
    if model is None:
        raise CameraError(f"{path}: camera {cam_id}: COLMAP model {cam.model} is not one splatgl "
                          f"renders; undistort the images first (supported: {', '.join(COLMAP)})")
    try:
        fx, fy, cx, cy, instance = model.from_colmap(cam.model, tuple(cam.params))
    except CameraError as exc:
        raise CameraError(f"{path}: camera {cam_id}: {exc}") from None
    return dict(fx=fx, fy=fy, cx=cx, cy=cy, model=instance)


def is_colmap_model(path: Path) -> bool:
    """Whether ``path`` is a folder holding a COLMAP model (.bin or .txt)."""
    return path.is_dir() and any((path / f"cameras{e}").is_file() and (path / f"images{e}").is_file()
                                 for e in (".bin", ".txt"))


def incomplete_model(root: Path) -> str | None:
    """What is missing where ``root`` (or its ``sparse/0``, ``sparse``) holds half a COLMAP
    model, e.g. ``"garden/sparse/0: COLMAP model with cameras.bin but no images.bin"``; else None."""
    for cand in (root, root / "sparse" / "0", root / "sparse"):
        for ext in (".bin", ".txt"):
            have = [n for n in ("cameras", "images", "points3D") if (cand / f"{n}{ext}").is_file()]
            missing = [n for n in ("cameras", "images") if n not in have]
            if have and missing:
                return (f"{cand}: COLMAP model with {', '.join(n + ext for n in have)} but no "
                        f"{' or '.join(n + ext for n in missing)}")
    return None


def find_model(root: Path) -> Path | None:
    """The COLMAP model folder of a dataset: ``root`` itself, ``root/sparse/0`` or ``root/sparse``."""
    for cand in (root, root / "sparse" / "0", root / "sparse"):
        if is_colmap_model(cand):
            return cand
    return None


def load_colmap(model_dir: Path, images_dir: Path | None = None) -> list[NamedCamera]:
    """The views of a COLMAP model, sorted by image name (the trainers' order).

    ``images_dir``, when given, is where the photographs are looked up by name.
    """
    model_dir = Path(model_dir)
    ext = ".bin" if (model_dir / "cameras.bin").is_file() and (model_dir / "images.bin").is_file() else ".txt"
    cam_path, img_path = model_dir / f"cameras{ext}", model_dir / f"images{ext}"
    if ext == ".bin":
        cams, images = _read_cameras_bin(cam_path), _read_images_bin(img_path)
    else:
        cams, images = _read_cameras_txt(cam_path), _read_images_txt(img_path)
    if not images:
        raise CameraError(f"{img_path}: the model has no images")
    views = []
    for name, q, t, cam_id in sorted(images, key=lambda im: im[0]):
        where = f"{img_path}: image {name!r}"
        if cam_id not in cams:
            raise CameraError(f"{where}: camera id {cam_id} is not in {cam_path}")
        if not (np.isfinite(q).all() and np.isfinite(t).all()) or not np.linalg.norm(q) > 0:
            raise CameraError(f"{where}: pose must be finite with a non-zero quaternion")
        rot = quat_to_rotmat(np.asarray(q, np.float64))
        check_rigid_pose(rot, f"{where}: quaternion's rotation")
        w2c = np.eye(4)
        w2c[:3, :3], w2c[:3, 3] = rot, t
        c = cams[cam_id]
        intrinsics = _intrinsics(cam_path, cam_id, c)
        try:
            camera = Camera(c.width, c.height, world_to_camera=w2c, **intrinsics)
        except CameraError as exc:
            raise CameraError(f"{cam_path}: camera {cam_id}: {exc}") from None
        image = images_dir / name if images_dir is not None and (images_dir / name).is_file() else None
        views.append(NamedCamera(name, camera, image))
    return views


# ------------------------------------------------------------------------------ writers (tests,
# and `splatgl path` users who want a model other tools read)
def write_colmap(model_dir: Path, views: list[NamedCamera], binary: bool = True) -> None:
    """Write ``views`` as a COLMAP model (one camera per view, in its model's COLMAP form:
    :meth:`~splatgl.cameras.model.CameraModel.to_colmap`; no 2D points).  A camera COLMAP has
    no model for raises CameraError before anything is written."""
    model_dir = Path(model_dir)
    poses = []
    for v in views:
        name, params = v.camera.model.to_colmap(v.camera)
        if _BY_NAME[name][1] != len(params):
            raise CameraError(f"COLMAP model {name} takes {_BY_NAME[name][1]} parameters, got {len(params)}")
        poses.append((v.name, rotmat_to_quat(v.camera.rotation), v.camera.translation, v.camera,
                      name, tuple(float(p) for p in params)))
    model_dir.mkdir(parents=True, exist_ok=True)
    if binary:
        cams = struct.pack("<Q", len(views))
        imgs = struct.pack("<Q", len(views))
        for i, (name, q, t, c, model, params) in enumerate(poses, 1):
            cams += struct.pack(f"<iiQQ{len(params)}d", i, _BY_NAME[model][0], c.width, c.height, *params)
            imgs += struct.pack("<idddddddi", i, *q, *t, i) + name.encode() + b"\0" + struct.pack("<Q", 0)
        (model_dir / "cameras.bin").write_bytes(cams)
        (model_dir / "images.bin").write_bytes(imgs)
    else:
        cams = ["# Camera list: CAMERA_ID, MODEL, WIDTH, HEIGHT, PARAMS[]"]
        imgs = ["# IMAGE_ID, QW, QX, QY, QZ, TX, TY, TZ, CAMERA_ID, NAME", "# POINTS2D[] as (X, Y, POINT3D_ID)"]
        for i, (name, q, t, c, model, params) in enumerate(poses, 1):
            cams.append(f"{i} {model} {c.width} {c.height} {' '.join(repr(p) for p in params)}")
            imgs.append(f"{i} {' '.join(repr(float(x)) for x in (*q, *t))} {i} {name}")
            imgs.append("")
        (model_dir / "cameras.txt").write_text("\n".join(cams) + "\n")
        (model_dir / "images.txt").write_text("\n".join(imgs) + "\n")
