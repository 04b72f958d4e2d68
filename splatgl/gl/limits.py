"""How large an image this machine can render, checked before anything is allocated.

Two limits apply, whatever gave the size (``--width``/``--height`` or a camera file):

- the OpenGL context's own: a side may not exceed ``GL_MAX_RENDERBUFFER_SIZE``,
  ``GL_MAX_TEXTURE_SIZE`` or ``GL_MAX_VIEWPORT_DIMS`` (quad path), and the tile renderer's
  per-pixel colour buffer (16 bytes a pixel) must fit ``GL_MAX_SHADER_STORAGE_BLOCK_SIZE``;
- the driver's allocation: no GL constant tells how large a texture the driver will allocate
  (llvmpipe refuses an RGBA32F texture of 16384x8192, 2 GiB, with GL_OUT_OF_MEMORY although
  every side is within its limits), so a quad-path colour target above :data:`PROBE_BYTES` is
  created once, empty, and released before any work (:func:`target_refused`); a framebuffer
  that still comes out incomplete is a one-line error too (:mod:`splatgl.gl.targets`);
- memory: the image buffers every renderer certainly allocates (:data:`MIN_BYTES_PER_PIXEL`)
  must fit the memory the kernel reports as available.

The splats' storage buffers (:mod:`splatgl.gl.scene_buffers`), and every per-splat, per-key
or per-pixel buffer derived from them, are refused before they are allocated when one would
exceed :func:`buffer_limit` (:func:`check_splat_buffer`): llvmpipe crashes the process reading
a buffer past 2 GiB.

Without a context (the NumPy reference) only the memory check and :data:`MAX_IMAGE_SIDE` apply.
Which renderer needs which check: :func:`splatgl.renderers.registry.image_size_problem`.
"""

from __future__ import annotations

from pathlib import Path

from ..errors import SplatglError
from ..scene.settings import Precision

#: Largest image side splatgl accepts before asking any context (the common GL 4.3 driver limit,
#: llvmpipe's included); the context's real limits are checked as well.
MAX_IMAGE_SIDE = 16384
#: Bytes per pixel every renderer allocates at least for one view with depth: the float32
#: colour target (16), the depth layer (16 on the GPU as an RGBA32F attachment, 4 read back) and
#: the float32 RGBA copy handed back (16).  A lower bound: the check never refuses a size that
#: would fit.
MIN_BYTES_PER_PIXEL = 52
#: The tile renderer's per-pixel RGBA32F output buffer, bytes per pixel (one SSBO).
TILE_RGBA_BYTES = 16
#: A quad-path colour target larger than this is tried on the context before any work (smaller
#: ones are within what every driver allocates; the try costs nothing on llvmpipe, which refuses
#: before allocating).
PROBE_BYTES = 256 << 20
#: ``GL_MAX_SHADER_STORAGE_BLOCK_SIZE`` assumed of a context that does not report it.
DEFAULT_BLOCK = 2 ** 27
#: The most bytes one storage buffer of splats may hold on any driver: shaders address storage
#: buffers with 32-bit byte offsets (llvmpipe reads a buffer of 2 GiB to its last word and
#: crashes the process, SIGSEGV, on one 4 bytes larger; it refuses 4 GiB with GL_OUT_OF_MEMORY).
MAX_BUFFER_BYTES = 2 ** 31
#: What :func:`check_splat_buffer` advises for the scene's own buffers, and for the buffers
#: derived from the splats each frame (projections, cull rows, keys: the storage does not change
#: their size).
SCENE_ADVICE = ("draw fewer splats (a smaller --lod-budget or --memory), store them smaller "
                "(--gpu-storage compact) or use --renderer cpu")
DERIVED_ADVICE = "draw fewer splats (a smaller --lod-budget or --memory) or use --renderer cpu"
#: The texel of each colour target precision: (moderngl dtype, bytes a pixel, GL name).
_TEXELS = {Precision.RGBA32F: ("f4", 16, "RGBA32F"), Precision.RGBA16F: ("f2", 8, "RGBA16F"),
           Precision.RGBA8: ("f1", 4, "RGBA8")}


def available_memory() -> int | None:
    """Bytes the kernel reports as available (``MemAvailable`` of /proc/meminfo), or None."""
    try:
        for line in Path("/proc/meminfo").read_text().splitlines():
            if line.startswith("MemAvailable:"):
                return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    return None


def _gib(n: float) -> str:
    return f"{n / 2**30:.1f} GiB"


def target_refused(ctx, width: int, height: int,
                   precision: Precision | str = Precision.RGBA32F) -> str | None:
    """Why ``ctx`` will not allocate a ``width`` x ``height`` colour target of ``precision``
    (tried once, empty, and released), or None; targets up to :data:`PROBE_BYTES` are not tried.
    A GL error pending before the try is cleared first (it is not this size's doing)."""
    dtype, texel, name = _TEXELS[Precision(precision)]
    nbytes = width * height * texel
    if nbytes <= PROBE_BYTES:
        return None
    ctx.error  # noqa: B018  (reading clears a pending error)
    texture = ctx.texture((width, height), 4, dtype=dtype)
    try:
        error = ctx.error
    finally:
        texture.release()
    if error == "GL_NO_ERROR":
        return None
    return (f"is larger than this OpenGL driver allocates (its {name} colour target of "
            f"{_gib(nbytes)} was refused with {error} by {ctx.info.get('GL_RENDERER', '?')})")


def side_problem(width: int, height: int, ctx=None) -> str | None:
    """Why an image side is too long: beyond ``ctx``'s own limits (``GL_MAX_RENDERBUFFER_SIZE``,
    ``GL_MAX_TEXTURE_SIZE``, ``GL_MAX_VIEWPORT_DIMS``), or without a context (a renderer that
    draws without OpenGL) beyond :data:`MAX_IMAGE_SIDE`; or None."""
    side = max(width, height)
    if ctx is None:
        return (f"is larger than splatgl renders ({MAX_IMAGE_SIDE} pixels a side)"
                if side > MAX_IMAGE_SIDE else None)
    info = ctx.info
    limits = [(int(info.get("GL_MAX_RENDERBUFFER_SIZE", MAX_IMAGE_SIDE)), "GL_MAX_RENDERBUFFER_SIZE"),
              (int(info.get("GL_MAX_TEXTURE_SIZE", MAX_IMAGE_SIDE)), "GL_MAX_TEXTURE_SIZE")]
    dims = info.get("GL_MAX_VIEWPORT_DIMS")
    if dims:
        limits.append((int(min(dims)), "GL_MAX_VIEWPORT_DIMS"))
    limit, name = min(limits)
    if side > limit:
        return (f"is larger than this OpenGL driver allows ({limit} pixels a side, {name} of "
                f"{info.get('GL_RENDERER', '?')})")
    return None


def pixel_buffer_refused(ctx, width: int, height: int, precision=None) -> str | None:
    """Why the tile renderer's per-pixel colour buffer (:data:`TILE_RGBA_BYTES` a pixel, one
    storage block) will not fit ``GL_MAX_SHADER_STORAGE_BLOCK_SIZE``, or None (``precision``:
    unused, as :func:`target_refused` takes it)."""
    block = storage_block_size(ctx)
    if width * height * TILE_RGBA_BYTES > block:
        return (f"has too many pixels for the tile renderer on this driver ({width * height:,}; "
                f"its colour buffer of {TILE_RGBA_BYTES} bytes a pixel may hold "
                f"{block // TILE_RGBA_BYTES:,}, GL_MAX_SHADER_STORAGE_BLOCK_SIZE)")
    return None


def storage_block_size(ctx) -> int:
    """``GL_MAX_SHADER_STORAGE_BLOCK_SIZE`` of ``ctx`` as it reports it (:data:`DEFAULT_BLOCK`
    where it does not): the tile renderer's limit on its key buffer."""
    return int(ctx.info.get("GL_MAX_SHADER_STORAGE_BLOCK_SIZE") or DEFAULT_BLOCK)


def buffer_limit(ctx) -> tuple[int, str]:
    """(bytes, what sets it): the largest one storage buffer of splats may be on ``ctx``.

    :data:`MAX_BUFFER_BYTES` everywhere; below it, ``GL_MAX_SHADER_STORAGE_BLOCK_SIZE`` where the
    driver enforces it.  llvmpipe reports 128 MiB but reads 2 GiB buffers to their last word
    (measured), and crashes the process (SIGSEGV) reading past 2 GiB: its limit is 2 GiB."""
    renderer = ctx.info.get("GL_RENDERER", "?")
    block = storage_block_size(ctx)
    if renderer.startswith("llvmpipe") or block >= MAX_BUFFER_BYTES:
        return MAX_BUFFER_BYTES, f"the most one buffer may hold on {renderer}"
    return block, f"GL_MAX_SHADER_STORAGE_BLOCK_SIZE of {renderer}"


def check_splat_buffer(ctx, count: int | None, nbytes: int, what: str, unit: str = "splats",
                       advice: str = SCENE_ADVICE) -> None:
    """Refuse, before it is allocated, a storage buffer of ``nbytes`` holding ``count`` items
    (``unit``: splats, tile keys; None: not counted) larger than :func:`buffer_limit` allows
    (``what`` names it): one line naming the count, the bytes, the limit and ``advice``.

    The one check for every GPU buffer whose size grows with the splats, the keys or the
    pixels: the scene's (:mod:`splatgl.gl.scene_buffers`), the per-view buffers
    (:class:`splatgl.gl.buffers.GrowableBuffer` checks each growth), the quad path's
    device-order cull rows, the tile renderer's projections and key buffers."""
    limit, source = buffer_limit(ctx)
    if nbytes > limit:
        need = f"{count:,} {unit} need" if count is not None else "it needs"
        raise SplatglError(
            f"{need} a GPU buffer of {nbytes:,} bytes ({what}), more than this OpenGL driver "
            f"allows in one ({limit:,} bytes, {source}); {advice}")


def memory_problem(width: int, height: int) -> str | None:
    """Why the image buffers every renderer allocates (:data:`MIN_BYTES_PER_PIXEL`) will not fit
    the available memory, or None."""
    need = width * height * MIN_BYTES_PER_PIXEL
    free = available_memory()
    if free is not None and need > free:
        return (f"needs at least {_gib(need)} of memory for its image buffers, "
                f"{_gib(free)} available")
    return None
