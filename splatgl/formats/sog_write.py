"""Writer of PlayCanvas SOG version 2 (``*.sog`` zip bundle, or ``meta.json`` with its textures
beside it), read back by :mod:`.sog`.

The layout is described in :mod:`splatgl.formats.sog`.  The writer quantises as that describes
(constants in :mod:`splatgl.formats.quantise`): 16-bit log means, 1D k-means codebooks of 256
entries (extremes kept, so the error is at most half the largest gap), 8-bit smallest-three
quaternions and opacity, and a k-means palette of SH vectors sized like splat-transform's
(``min(64, 2^floor(log2(N / 1024))) * 1024`` entries, at most N).  Splats are written in Morton
order (smaller WebP files); :func:`write` returns that order.
"""

from __future__ import annotations

import json
import math
import zipfile
from pathlib import Path

import numpy as np

from ..constants import SH_C0
from ..scene.spatial import morton_order_full_box
from ..errors import SceneFormatError
from ..scene.splats import Scene, SplatKind
from . import kmeans, sog_folder, webp
from . import quantise as qz
from .sog import EXTENSIONS, NAME  # noqa: F401 (the format registry reads them here too)

GENERATOR = "splatgl"
#: The version 2 files of each attribute, as meta.json names them.
FILES_V2 = {"means": ("means_l.webp", "means_u.webp"), "scales": ("scales.webp",),
            "quats": ("quats.webp",), "sh0": ("sh0.webp",),
            "shN": ("shN_centroids.webp", "shN_labels.webp")}


def palette_size(count: int) -> int:
    """Entries of the SH palette for ``count`` splats (splat-transform's rule), at most count."""
    size = min(64.0, 2.0 ** math.floor(math.log2(count / 1024.0))) * 1024.0
    return max(1, min(count, int(size)))


def _texture_size(count: int) -> tuple[int, int]:
    width = math.ceil(math.sqrt(count) / 4) * 4
    return width, math.ceil(count / width / 4) * 4


def _log_means(means: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    v = np.sign(means) * np.log1p(np.abs(means))
    return v, v.min(axis=0), v.max(axis=0)


def encode(scene: Scene, iterations: int = qz.SOG_KMEANS_ITERATIONS, path=None
           ) -> tuple[dict[str, np.ndarray], dict]:
    """The textures (name -> (H, W, 4) uint8) and meta.json object of ``scene`` (in its order)."""
    if scene.kind is not SplatKind.GAUSSIAN_3D:
        raise SceneFormatError(path, "SOG stores 3D Gaussians only; cannot write a 2DGS surfel "
                                     "scene (write .ply instead)", "scale")
    n = scene.count
    width, height = _texture_size(n)
    if width > webp.MAX_EDGE or height > webp.MAX_EDGE:
        raise SceneFormatError(path, f"{n} splats exceed WebP's {webp.MAX_EDGE}-texel edge", "count")

    def texture(rgb: np.ndarray, alpha) -> np.ndarray:
        out = np.zeros((width * height, 4), np.uint8)
        out[:, 3] = 255
        out[:n, : rgb.shape[1]] = rgb
        out[:n, 3] = alpha
        return out.reshape(height, width, 4)

    v, mins, maxs = _log_means(scene.means.astype(np.float64))
    span = np.where(maxs > mins, maxs - mins, 1.0)
    u = np.clip(np.rint((v - mins) / span * 65535.0), 0, 65535).astype(np.uint32)
    tex = {"means_l.webp": texture(u & 255, 255), "means_u.webp": texture(u >> 8, 255)}
    largest, abc = qz.smallest_three(scene.rotations)
    quat = np.clip(np.rint(255.0 * (abc * math.sqrt(2.0) * 0.5 + 0.5)), 0, 255)
    tex["quats.webp"] = texture(quat, qz.SOG_QUAT_TAG + largest)
    scale_book = qz.codebook_1d(scene.log_scales).astype(np.float32)
    tex["scales.webp"] = texture(qz.codebook_labels(scene.log_scales, scale_book), 255)
    dc_book = qz.codebook_1d(scene.sh[:, 0]).astype(np.float32)
    alpha = np.clip(np.rint(scene.opacities.astype(np.float64) * 255.0), 0, 255)
    tex["sh0.webp"] = texture(qz.codebook_labels(scene.sh[:, 0], dc_book), alpha)
    meta = {"version": 2, "asset": {"generator": GENERATOR}, "count": n,
            "means": {"mins": mins.tolist(), "maxs": maxs.tolist(),
                      "files": list(FILES_V2["means"])},
            "scales": {"codebook": scale_book.tolist(), "files": list(FILES_V2["scales"])},
            "quats": {"files": list(FILES_V2["quats"])},
            "sh0": {"codebook": dc_book.tolist(), "files": list(FILES_V2["sh0"])}}
    if scene.sh_degree > 0:
        coeffs = scene.sh.shape[1] - 1
        rest = scene.sh[:, 1:].reshape(n, coeffs * 3)
        centroids, labels = kmeans.kmeans(rest, palette_size(n), iterations)
        k = centroids.shape[0]
        book = qz.codebook_1d(centroids).astype(np.float32)
        cen = np.zeros((math.ceil(k / 64) * 64, coeffs, 4), np.uint8)
        cen[..., 3] = 255
        cen[:k, :, :3] = qz.codebook_labels(centroids.reshape(k, coeffs, 3), book)
        tex["shN_centroids.webp"] = cen.reshape(-1, 64 * coeffs, 4)
        lab = np.stack([labels & 255, labels >> 8], axis=1)
        tex["shN_labels.webp"] = texture(lab, 255)
        meta["shN"] = {"count": k, "bands": scene.sh_degree, "codebook": book.tolist(),
                       "files": list(FILES_V2["shN"])}
    return tex, meta


def writes_folder(target) -> bool:
    """Whether ``target`` names the folder form (meta.json and its textures), which
    :func:`write` publishes itself, as a whole (:mod:`splatgl.formats.sog_folder`), rather than
    into one temporary."""
    return Path(target).name.lower().endswith(".json")


def write(path, scene: Scene, iterations: int = qz.SOG_KMEANS_ITERATIONS, target=None) -> np.ndarray:
    """Write ``scene`` to ``path`` as SOG v2: a zip bundle (``path`` may be a temporary), or
    (for a file name ``target``, default ``path``, ending in ``.json``) meta.json with its
    textures beside it, replacing an older scene there as a whole
    (:func:`splatgl.formats.sog_folder.publish`; ``path`` is then not written).  Returns the
    (N,) row order written (Morton order)."""
    path = Path(path)
    target = Path(target) if target is not None else path
    order = morton_order_full_box(scene.means)
    textures, meta = encode(scene.subset(order), iterations, target)
    blobs = {name: webp.encode(rgba) for name, rgba in textures.items()}
    if writes_folder(target):
        sog_folder.publish(target, blobs, meta)
        return order
    meta_bytes = json.dumps(meta).encode("utf-8")
    with zipfile.ZipFile(path, "w", zipfile.ZIP_STORED) as zf:  # WebP is compressed already
        for name, blob in blobs.items():
            zf.writestr(name, blob)
        zf.writestr("meta.json", meta_bytes)
    return order


def error_bounds(scene: Scene) -> dict:
    """Per-attribute round-trip error bounds (see :mod:`splatgl.formats.quantise`); ``sh_rest``
    is None: the k-means palette has no a-priori bound (its error is measured and reported)."""
    v, mins, maxs = _log_means(scene.means.astype(np.float64))
    half = (maxs - mins) / 65535.0 / 2.0
    vmax = np.maximum(np.abs(mins), np.abs(maxs))
    per_axis = np.exp(vmax) * np.expm1(half * (1 + 1e-9))
    position = float(np.linalg.norm(per_axis)) * (1 + 1e-6) + qz.position_slack(scene.means)
    scale_book = qz.codebook_1d(scene.log_scales).astype(np.float32)
    dc_book = qz.codebook_1d(scene.sh[:, 0]).astype(np.float32)
    return {
        "position": position,
        "scale": qz.relative_scale(qz.codebook_bound(scale_book, scene.log_scales)) + 1e-6,
        "opacity": 0.5 / 255.0 + 1e-6,
        "rotation": qz.half_step_rotation_deg(1.0 / (255.0 * math.sqrt(2.0))),
        "color": SH_C0 * qz.codebook_bound(dc_book, scene.sh[:, 0]) + 1e-7,
        "sh_rest": None,
    }
