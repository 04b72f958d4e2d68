"""Triangle meshes to composite splats with (``--under``), and the NumPy twin of their
rasterisation (shaders/mesh.vert, mesh.frag; :class:`splatgl.renderers.mesh.MeshRenderer`).

A :class:`Mesh` is flat-shaded triangles in world coordinates with a colour per face.  Its
closed form at a pixel is the nearest hit of the ray through the pixel centre
(:func:`ray_depth`, Moeller-Trumbore): the depth the GPU's perspective-correct interpolation of
view z gives there, since view z is linear over a triangle.  :func:`box` and :func:`plane`
build the test shapes.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..cameras.camera import Camera
from ..errors import CameraError


@dataclass(frozen=True)
class Mesh:
    """``vertices`` (V, 3) float64 world points, ``faces`` (F, 3) int vertex indices
    (counter-clockwise or not: both sides are drawn), ``colors`` (F, 3) float RGB per face."""

    vertices: np.ndarray
    faces: np.ndarray
    colors: np.ndarray

    def __post_init__(self) -> None:
        object.__setattr__(self, "vertices", np.asarray(self.vertices, np.float64).reshape(-1, 3))
        object.__setattr__(self, "faces", np.asarray(self.faces, np.int64).reshape(-1, 3))
        colors = np.asarray(self.colors, np.float64)
        object.__setattr__(self, "colors", np.broadcast_to(colors, (len(self.faces), 3)).copy())

    def triangles(self) -> np.ndarray:
        """(F, 3, 3) the corners of every face."""
        return self.vertices[self.faces]

    def __add__(self, other: "Mesh") -> "Mesh":
        return Mesh(np.concatenate([self.vertices, other.vertices]),
                    np.concatenate([self.faces, other.faces + len(self.vertices)]),
                    np.concatenate([self.colors, other.colors]))


def box(center, size, color=(0.8, 0.8, 0.8), rotation: np.ndarray | None = None) -> Mesh:
    """An axis-aligned box (``size``: edge lengths, or one for a cube) turned by ``rotation``
    (3, 3) about its centre: 12 triangles."""
    half = 0.5 * np.broadcast_to(np.asarray(size, np.float64), (3,))
    corners = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], np.float64) * half
    if rotation is not None:
        corners = corners @ np.asarray(rotation, np.float64).T
    quads = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    faces = [f for a, b, c, d in quads for f in ((a, b, c), (a, c, d))]
    return Mesh(corners + np.asarray(center, np.float64), faces, color)


def plane(center, u_axis, v_axis, color=(0.8, 0.8, 0.8)) -> Mesh:
    """The parallelogram ``center + s u_axis + t v_axis``, ``|s|, |t| <= 1``: two triangles."""
    c, u, v = (np.asarray(a, np.float64) for a in (center, u_axis, v_axis))
    return Mesh([c - u - v, c + u - v, c + u + v, c - u + v], [(0, 1, 2), (0, 2, 3)], color)


def check_camera(camera: Camera) -> None:
    """Straight triangle edges stay straight only in perspective and orthographic images."""
    if camera.model.depth_is_distance:
        raise CameraError(f"the mesh renderer draws straight-edged triangles: perspective and "
                          f"orthographic cameras only, not {camera.model.name}")


def pixel_rays(camera: Camera) -> tuple[np.ndarray, np.ndarray]:
    """(H, W, 3) camera-space ray origins and directions through the pixel centres (directions
    with z = 1, so a hit's ray parameter is its view z)."""
    check_camera(camera)
    u = np.arange(camera.width) + 0.5
    v = np.arange(camera.height) + 0.5
    uu, vv = np.meshgrid(u, v)
    x, y = (uu - camera.cx) / camera.fx, (vv - camera.cy) / camera.fy
    if camera.model.parallel_rays:
        origin = np.stack([x, y, np.zeros_like(x)], -1)
        return origin, np.broadcast_to(np.array([0.0, 0.0, 1.0]), origin.shape)
    return np.zeros(uu.shape + (3,)), np.stack([x, y, np.ones_like(x)], -1)


def ray_depth(mesh: Mesh, camera: Camera) -> tuple[np.ndarray, np.ndarray]:
    """The closed form: (H, W) float64 view z of the nearest hit in front of the camera
    (+inf: none) and (H, W) int64 its face (-1: none), float64 throughout."""
    origin, direction = pixel_rays(camera)
    rot, t = camera.rotation, camera.translation
    tri = mesh.triangles() @ rot.T + t                       # (F, 3, 3) camera space
    best = np.full(origin.shape[:2], np.inf)
    face = np.full(origin.shape[:2], -1, np.int64)
    o, d = origin.reshape(-1, 3), direction.reshape(-1, 3)
    for k, (a, b, c) in enumerate(tri):
        e1, e2 = b - a, c - a
        p = np.cross(d, e2)
        det = p @ e1
        with np.errstate(divide="ignore", invalid="ignore"):
            inv = 1.0 / det
            s = o - a
            bu = (s * p).sum(-1) * inv
            q = np.cross(s, e1)
            bv = (d * q).sum(-1) * inv
            z = (q @ e2) * inv
        hit = (np.abs(det) > 1e-15) & (bu >= 0) & (bv >= 0) & (bu + bv <= 1) & (z > 0)
        z = np.where(hit, z, np.inf).reshape(best.shape)
        closer = z < best
        best = np.where(closer, z, best)
        face = np.where(closer, k, face)
    return best, face
