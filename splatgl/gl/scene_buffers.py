"""The static scene on the GPU: storage buffers uploaded once (layouts in shaders/lib/scene.glsl)."""

from __future__ import annotations

import math

import moderngl
import numpy as np

from ..constants import glsl_float
from ..scene.splats import Scene
from ..scene.settings import GpuStorage
from .bindings import BINDING_A, BINDING_DC, BINDING_Q, BINDING_S, BINDING_SH
from .limits import check_splat_buffer
from .storage import COMPACT_WORDS, encode_compact, scale_exponent


#: Rows per upload chunk: the only CPU-side copy of the GPU layout is one chunk's worth.
UPLOAD_ROWS = 1 << 16


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

    FLOAT32 and HALF_SH: ``a`` = (mean.xyz - scene.anchor, opacity), ``q`` = unit quaternion,
    ``s`` = (scale.xyz, 0) for 3DGS or (scale.xy, 0, 0) for surfels, ``dc`` = (SH DC RGB, 0).
    COMPACT: ``packed`` = 8 uint32 per splat (:mod:`splatgl.gl.storage`), ``a``/``q``/``s``/``dc``
    None.  ``sh`` = coefficients 1..K-1 (K-1 x 3 per splat, float32, or float16 packed two per
    uint with HALF_SH and COMPACT; absent at degree 0).  Stored at the scene's own degree:
    nothing is padded to degree 3.  :meth:`defines` specialises the shaders for the layout.

    Uploaded :data:`UPLOAD_ROWS` rows at a time into buffers reserved at their final size,
    activating each chunk on the way (:meth:`Scene.activated_rows`): no full-size activated or
    packed copy of the scene exists on the CPU.
    """

    def __init__(self, ctx: moderngl.Context, scene: Scene,
                 storage: GpuStorage = GpuStorage.FLOAT32):
        n = scene.count
        self.scene = scene
        self.count = n
        self.sh_rest_coeffs = scene.sh.shape[1] - 1
        self.storage = storage = GpuStorage(storage)
        self.half_sh = half_sh = storage is not GpuStorage.FLOAT32
        compact = storage is GpuStorage.COMPACT
        #: Per-scene power of two of the compact scales (splatgl.gl.storage.scale_exponent).
        self.scale_exponent = scale_exponent(scene.log_scales) if compact else 0
        # Means relative to the scene's anchor (float32-safe far from the origin); the camera
        # uniforms fold the anchor back in (splatgl.cameras.view.anchored_camera).
        self.a = self.q = self.s = self.dc = self.packed = None
        rest_values = self.sh_rest_coeffs * 3
        rest_bytes = rest_values * (2 if half_sh else 4)
        if half_sh and (n * rest_values) % 2:
            rest_bytes_total = n * rest_bytes + 2  # whole uints
        else:
            rest_bytes_total = n * rest_bytes
        base = 4 * COMPACT_WORDS if compact else 16
        largest = max((base * n, f"--gpu-storage {storage.value}, {base} bytes a splat"),
                      (rest_bytes_total, f"SH degree {scene.sh_degree} at --gpu-storage "
                                         f"{storage.value}, {rest_bytes} bytes a splat"))
        check_splat_buffer(ctx, n, *largest)   # before any is allocated (llvmpipe: SIGSEGV)
        if compact:
            self.packed = ctx.buffer(reserve=4 * COMPACT_WORDS * max(n, 1))
        else:
            self.a, self.q, self.s, self.dc = (ctx.buffer(reserve=16 * max(n, 1)) for _ in range(4))
        self.sh = ctx.buffer(reserve=max(rest_bytes_total, 4)) if self.sh_rest_coeffs > 0 else None
        for start in range(0, n, UPLOAD_ROWS):
            stop = min(n, start + UPLOAD_ROWS)
            m = stop - start
            rows = scene.activated_rows(start, stop)
            if compact:
                words = encode_compact(rows.relative_means, rows.opacities, rows.rotations,
                                       rows.scales, scene.sh[start:stop, 0], self.scale_exponent)
                self.packed.write(words.tobytes(), offset=4 * COMPACT_WORDS * start)
            else:
                self.a.write(_vec4([rows.relative_means, rows.opacities], m).tobytes(), offset=16 * start)
                self.q.write(rows.rotations.tobytes(), offset=16 * start)
                self.s.write(_vec4([rows.scales], m).tobytes(), offset=16 * start)
                self.dc.write(_vec4([scene.sh[start:stop, 0]], m).tobytes(), offset=16 * start)
            if self.sh is not None:
                rest = np.ascontiguousarray(scene.sh[start:stop, 1:],
                                            np.float16 if half_sh else np.float32)
                self.sh.write(rest.tobytes(), offset=rest_bytes * start)

    def _bound(self) -> list[tuple[int, moderngl.Buffer]]:
        """(binding, buffer) of every buffer this layout has."""
        pairs = ((BINDING_A, self.packed if self.packed is not None else self.a),
                 (BINDING_Q, self.q), (BINDING_S, self.s), (BINDING_DC, self.dc),
                 (BINDING_SH, self.sh))
        return [(b, buf) for b, buf in pairs if buf is not None]

    @property
    def nbytes(self) -> int:
        """GPU bytes of the scene's storage buffers."""
        return sum(buf.size for _, buf in self._bound())

    def defines(self) -> dict[str, object]:
        """The #defines that make shaders/lib/scene.glsl read this layout."""
        out: dict[str, object] = {}
        if self.half_sh:
            out["SH_HALF"] = 1
        if self.storage is GpuStorage.COMPACT:
            out["COMPACT_STORAGE"] = 1
            out["COMPACT_SCALE_UNIT"] = glsl_float(math.ldexp(1.0, self.scale_exponent))
        return out

    def bind(self) -> None:
        for binding, buf in self._bound():
            buf.bind_to_storage_buffer(binding)

    def release(self) -> None:
        for _, buf in self._bound():
            buf.release()
        self.a = self.q = self.s = self.dc = self.packed = self.sh = None
