"""The static scene on the GPU: storage buffers uploaded once (layouts in shaders/lib/scene.glsl)."""

from __future__ import annotations

import moderngl
import numpy as np

from ..scene import Scene

BINDING_A, BINDING_Q, BINDING_S, BINDING_DC, BINDING_SH = 0, 1, 2, 3, 4


def _vec4(columns: list[np.ndarray], n: int) -> np.ndarray:
    out = np.zeros((n, 4), np.float32)
    col = 0
    for arr in columns:
        arr = arr.reshape(n, -1)
        out[:, col:col + arr.shape[1]] = arr
        col += arr.shape[1]
    return out


class SceneBuffers:
    """Activated splat attributes in std430 storage buffers; release with :meth:`release`.

    ``a`` = (mean.xyz - scene.anchor, opacity), ``q`` = unit quaternion, ``s`` = (scale.xyz, 0) for 3DGS or
    (scale.xy, 0, 0) for surfels, ``dc`` = (SH DC RGB, 0), ``sh`` = coefficients 1..K-1
    (K-1 x 3 per splat, float32 or with ``half_sh`` float16 packed two per uint; absent at
    degree 0).  Stored at the scene's own degree: nothing is padded to degree 3.
    """

    def __init__(self, ctx: moderngl.Context, scene: Scene, half_sh: bool = False):
        n = scene.count
        self.scene = scene
        self.count = n
        self.sh_rest_coeffs = scene.sh.shape[1] - 1
        # Means relative to the scene's anchor (float32-safe far from the origin); the camera
        # uniforms fold the anchor back in (splatgl.quad.set_camera_uniforms).
        self.a = ctx.buffer(_vec4([scene.relative_means, scene.opacities], n).tobytes())
        self.q = ctx.buffer(np.ascontiguousarray(scene.rotations, np.float32).tobytes())
        self.s = ctx.buffer(_vec4([scene.scales], n).tobytes())
        self.dc = ctx.buffer(_vec4([scene.sh[:, 0]], n).tobytes())
        self.half_sh = half_sh
        rest = np.ascontiguousarray(scene.sh[:, 1:], np.float16 if half_sh else np.float32).ravel()
        if half_sh and rest.size % 2:
            rest = np.concatenate([rest, np.zeros(1, np.float16)])  # whole uints
        self.sh = ctx.buffer(rest.tobytes()) if self.sh_rest_coeffs > 0 else None

    def bind(self) -> None:
        self.a.bind_to_storage_buffer(BINDING_A)
        self.q.bind_to_storage_buffer(BINDING_Q)
        self.s.bind_to_storage_buffer(BINDING_S)
        self.dc.bind_to_storage_buffer(BINDING_DC)
        if self.sh is not None:
            self.sh.bind_to_storage_buffer(BINDING_SH)

    def release(self) -> None:
        for buf in (self.a, self.q, self.s, self.dc, self.sh):
            if buf is not None:
                buf.release()
        self.sh = None
