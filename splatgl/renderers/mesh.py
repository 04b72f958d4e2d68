"""A small mesh rasterizer: opaque flat-shaded triangles (:class:`splatgl.splatmath.mesh.Mesh`)
drawn through OpenGL with the camera's own pixel mapping, giving the colour and view-space z
that ``--under`` composites splats into (:mod:`splatgl.output.under`).

The corners are moved into camera space in float64 on the CPU; the vertex stage maps them with
the camera's intrinsics exactly as the splats are mapped (pixel centres at ``j + 0.5``, row 0 at
the top); the depth buffer removes hidden surfaces and a float target keeps the interpolated
view z, which is exact at a pixel centre (z is linear on a triangle, and the interpolation is
perspective-correct): :func:`splatgl.splatmath.mesh.ray_depth` is its closed form.  Shading is a
headlight along the view axis: ``colour (AMBIENT + (1 - AMBIENT) |n_z|)`` (camera space), so the
two triangles of a flat quad shade alike.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import moderngl
import numpy as np

from ..cameras.camera import Camera
from ..gl.shaders import ProgramCache
from ..output.under import DepthKind, UnderImage
from ..splatmath.mesh import Mesh, check_camera

#: Light every face gets whatever its angle.
AMBIENT = 0.35


@dataclass(frozen=True)
class MeshImage:
    """``rgb`` (H, W, 3) float32 (the background where no face), ``alpha`` (H, W) 1 on faces,
    ``depth`` (H, W) float32 view z (+inf where no face); row 0 at the top."""

    rgb: np.ndarray
    alpha: np.ndarray
    depth: np.ndarray

    def under(self, path: Path | str = "<mesh>") -> UnderImage:
        """As ``--under`` geometry (premultiplied colour, view-space z)."""
        return UnderImage(self.rgb * self.alpha[..., None], self.alpha, self.depth, DepthKind.Z,
                          Path(path))

    @property
    def rgba(self) -> np.ndarray:
        """(H, W, 4) float32 colour and alpha, as an ``--under`` file holds them
        (:func:`splatgl.imagefiles.under_exr.write_under` writes it with :attr:`depth`)."""
        return np.concatenate([self.rgb, self.alpha[..., None]], -1)


def shaded_corners(mesh: Mesh, camera: Camera) -> tuple[np.ndarray, np.ndarray]:
    """(3F, 3) float32 camera-space corners and (3F, 3) float32 shaded face colours."""
    tri = mesh.triangles() @ camera.rotation.T + camera.translation      # float64
    normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    normal /= np.maximum(np.linalg.norm(normal, axis=1, keepdims=True), 1e-300)
    light = AMBIENT + (1.0 - AMBIENT) * np.abs(normal[:, 2])   # n . (0, 0, 1): the view axis
    colors = np.repeat(mesh.colors * light[:, None], 3, axis=0)
    return tri.reshape(-1, 3).astype(np.float32), colors.astype(np.float32)


class MeshRenderer:
    """Draws meshes on a context (``ctx``); :meth:`release` when done."""

    def __init__(self, ctx: moderngl.Context, programs: ProgramCache | None = None):
        self.ctx = ctx
        self.programs = programs or ProgramCache(ctx)

    def render(self, mesh: Mesh, camera: Camera, background=(0.0, 0.0, 0.0)) -> MeshImage:
        """``mesh`` seen by ``camera`` (perspective or orthographic; others refused)."""
        check_camera(camera)
        ctx, (w, h) = self.ctx, (camera.width, camera.height)
        pos, col = shaded_corners(mesh, camera)
        defines = {"ORTHOGRAPHIC": 1} if camera.model.parallel_rays else {}
        prog = self.programs.program("mesh.vert", "mesh.frag", defines)
        z = pos[:, 2].astype(np.float64)
        far = float(max(z.max(), 1e-6)) * 2.0
        front = z[z > 0]
        # Perspective: the near plane just before the nearest corner in front (a closer one
        # costs the depth buffer its precision between nearby faces), clipping what is behind.
        near = (max(0.5 * float(front.min()), far * 1e-5) if front.size else far * 1e-5) \
            if not camera.model.parallel_rays else float(min(z.min(), 0.0)) - 1.0
        a, b = (far + near) / (far - near), -2.0 * far * near / (far - near)
        if camera.model.parallel_rays:   # linear: z_ndc = a z + b over [near, far]
            a, b = 2.0 / (far - near), -(far + near) / (far - near)
        for name, value in (("u_intrinsics", (camera.fx, camera.fy, camera.cx, camera.cy)),
                            ("u_viewport", (float(w), float(h))), ("u_depth_map", (a, b))):
            if name in prog:
                prog[name].value = value
        color_tex = ctx.texture((w, h), 4, dtype="f4")
        z_tex = ctx.texture((w, h), 4, dtype="f4")
        depth = ctx.depth_renderbuffer((w, h))
        fbo = ctx.framebuffer([color_tex, z_tex], depth)
        vbo = ctx.buffer(np.concatenate([pos, col], 1).astype(np.float32).tobytes())
        vao = ctx.vertex_array(prog, [(vbo, "3f 3f", "in_pos", "in_color")])
        try:
            fbo.use()
            ctx.viewport = (0, 0, w, h)
            fbo.depth_mask = True
            fbo.clear(0.0, 0.0, 0.0, 0.0, depth=1.0)
            ctx.disable(moderngl.BLEND | moderngl.CULL_FACE)
            ctx.enable(moderngl.DEPTH_TEST)
            ctx.depth_func = "<"
            vao.render(moderngl.TRIANGLES)
            ctx.disable(moderngl.DEPTH_TEST)
            rgba = np.frombuffer(fbo.read(components=4, dtype="f4", attachment=0),
                                 np.float32).reshape(h, w, 4)
            zz = np.frombuffer(fbo.read(components=4, dtype="f4", attachment=1),
                               np.float32).reshape(h, w, 4)
        finally:
            ctx.detect_framebuffer(0).use()
            for obj in (vao, vbo, fbo, depth, color_tex, z_tex):
                obj.release()
        alpha = rgba[..., 3].copy()
        hit = alpha > 0
        rgb = np.where(hit[..., None], rgba[..., :3], np.asarray(background, np.float32))
        return MeshImage(rgb.astype(np.float32), alpha, np.where(hit, zz[..., 0], np.inf).astype(np.float32))

    def release(self) -> None:
        """Nothing is kept between renders (the programs belong to the cache)."""
