"""Reference constants of the per-tile 3DGS rasterizer (DESIGN.md section 2), in one place.

Python code imports these names; GLSL receives them as generated ``#define`` lines from
:func:`glsl_defines`, so no constant is ever typed twice.
"""

from __future__ import annotations

import math

#: Tile edge in pixels (the reference bins splats into 16 x 16 tiles).
TILE_SIZE = 16
#: Default near-plane distance of the reference (view-space z <= this is culled).  splatgl's own
#: default is scene-relative (see :func:`splatgl.scene.settings.resolve_near`), never larger than this.
REFERENCE_NEAR = 0.2
#: ``x/z`` and ``y/z`` are clamped to +-JACOBIAN_CLAMP * tan(half fov) inside the Jacobian only.
JACOBIAN_CLAMP = 1.3
#: Low-pass dilation added to both diagonal entries of the 2D covariance, in pixels^2.
LOW_PASS = 0.3
#: Floor of the antialiasing opacity compensation factor sqrt(det / det_dilated).
AA_MIN_FACTOR = 2.5e-5
#: Floor of the eigenvalue discriminant when computing the extent (``max(0.1, mid^2 - det)``).
EXTENT_DISCRIMINANT_FLOOR = 0.1
#: ``det = a c - b^2`` of the 2D covariance is trusted where it exceeds this fraction of ``a c``
#: (cancellation then costs at most ~eps / ratio, ~6e-6 relative in float32); below it the
#: renderers use the cancellation-free form (:func:`splatgl.splatmath.project.covariance_2d_det`).
DET_CANCEL_RATIO = 1e-2
#: Extent of the reference in standard deviations (radius ``ceil(3 sqrt(lambda_max))``).
EXTENT_SIGMAS = 3.0
#: Largest extent (pixels) a splat's radius is clamped to, so that it fits an int64; far beyond
#: any image (a larger radius covers the same tiles).
MAX_RADIUS = float(2 ** 52)
#: Upper clamp of a splat's alpha.
ALPHA_MAX = 0.99
#: Smallest alpha that contributes; smaller ones are skipped (and discarded on the GPU).
ALPHA_MIN = 1.0 / 255.0
#: Front-to-back blending stops when the transmittance would fall below this.
T_MIN = 1e-4
#: The median-depth layer takes the depth of the last splat blended while the transmittance
#: before it is above this (2DGS's and gsplat's median: where the accumulated alpha crosses 0.5).
MEDIAN_T = 0.5
#: Fixed quad half-size, in standard deviations, of the fast approximation (``--extent fast``):
#: 2 sqrt(2), the corner distance web viewers use (their corner coordinate 2 times sqrt(2) sigma).
FAST_CORNER_SIGMAS = 2.0 * math.sqrt(2.0)
#: The per-pixel order (``--order per-pixel``) clamps the depth of a splat's peak along a ray to
#: this many standard deviations of its view depth about its centre (splatgl/splatmath/peak.py).
PEAK_CLAMP_SIGMAS = 3.0
#: Entries of a tile's sorted list one tile-renderer rasterize pass blends at most; longer lists
#: take more passes (the pixel state carried in the output buffers), and the per-pixel order's
#: window restarts at each pass (its twin, :func:`splatgl.reference.per_pixel.window_order`).
#: llvmpipe ends all loops of an invocation after 65535 iterations in total (gallivm's
#: LP_MAX_TGSI_LOOP_ITERATIONS), which a single pass over a 55k-splat tile exceeded, leaving the
#: tile blank; a pass of 16384 entries runs about 2 x 16384 + 64 iterations (the blend loop, and
#: the serial scan of invocation 0).
TILE_LIST_CHUNK = 16384
#: The other published convention (gsplat), for ``Compat.GSPLAT``: per-axis opacity-aware extent
#: of at most this many standard deviations, and its alpha clamp.
GSPLAT_EXTENT_SIGMAS = 3.33
GSPLAT_ALPHA_MAX = 0.999
#: gsplat's floor on a 2DGS surfel's squared 1-sigma screen half extent (px^2) before the
#: ``ceil(3.33 sqrt(.))`` of its per-axis tile radius.
GSPLAT_SURFEL_MIN_EXTENT_SQ = 1e-4
#: |logit| bound for opacities of exactly 0 or 1 (8-bit alphas 0/255, ``from_activated``), so
#: every stored logit stays finite; sigmoid(40) rounds to 1.0 in float32.
MAX_LOGIT = 40.0
#: Linear scale used in place of an exact 0 before taking the log, so stored log-scales stay finite.
MIN_SCALE = 1e-38
#: Constant added to the SH colour before the clamp at 0.
SH_OFFSET = 0.5
#: 2DGS screen-space low-pass (the official rasterizer's ``FilterInvSquare``): a surfel's
#: Gaussian value at pixel x is ``max(G(u(x)), exp(-0.5 F |x - c|^2))`` with F this value, i.e.
#: a screen disc of sigma 1/sqrt(F) = sqrt(2)/2 px around the projected centre c.
SURFEL_FILTER_INV_SQUARE = 2.0

#: A camera pose read from a file must be rigid: its 3x3 rotation R may differ from an orthonormal
#: matrix with det +1 by at most this much (largest entry of |R R^T - I|, and |det R - 1|).  Poses
#: saved as float32 keep ~1e-7; 1e-4 also accepts JSON written with 5-6 significant digits.
RIGID_POSE_TOLERANCE = 1e-4
#: Fisheye cameras (:mod:`splatgl.cameras.fisheye`) keep splat centres up to this angle (radians, 10
#: degrees) beyond the largest angle from the axis that reaches the image, so splats centred
#: just outside the view still reach in, as the pinhole's rectangle test allows ...
FISHEYE_THETA_MARGIN = math.radians(10.0)
#: ... but never beyond this angle from the axis: at theta = pi every direction maps onto one
#: circle and the linearisation breaks down (the last ~0.6 degrees around the antipode of a
#: 360-degree fisheye are not drawn).
FISHEYE_THETA_CAP = math.pi - 1e-2
#: Below ``rho = this * z`` the fisheye map's ``g / rho`` and its Jacobian term cancel; their
#: series in ``(rho / z)^2`` are used there (relative error below 1e-8 in ``s``).
FISHEYE_SERIES_RHO = 1e-2
#: Floor of an equirectangular splat's distance from the polar axis, as a fraction of its
#: distance: keeps the longitude row of the Jacobian finite at the poles.
EQUIRECT_POLE_EPS = 1e-4

# Real spherical-harmonics basis constants (trig-free polynomial form), degrees 0..3.
SH_C0 = 0.28209479177387814
SH_C1 = 0.4886025119029199
SH_C2 = (
    1.0925484305920792,
    -1.0925484305920792,
    0.31539156525252005,
    -1.0925484305920792,
    0.5462742152960396,
)
SH_C3 = (
    -0.5900435899266435,
    2.890611442640554,
    -0.4570457994644658,
    0.3731763325901154,
    -0.4570457994644658,
    1.445305721320277,
    -0.5900435899266435,
)
MAX_SH_DEGREE = 3


#: GPU radix sort (shaders/radix_*.comp, splatgl/gl/radix_sort.py): bits per pass (256 digit
#: values), keys per thread.  A group of RADIX_GROUP threads (splatgl/gl/bindings.py, 128)
#: sorts one tile of RADIX_GROUP * RADIX_ITEMS = 4096 keys per pass; at most 4 passes cover
#: 32-bit keys, fewer where the keys share bits.
RADIX_BITS = 8
RADIX_ITEMS = 32
#: The block passes of the radix sort on software devices (shaders/radix_block_*.comp,
#: splatgl/gl/radix_block.py): bits per pass (2048 digit values, counted in a private array per
#: lane), so 32-bit keys take at most 3 passes.
RADIX_BLOCK_BITS = 11

#: The tile renderer's device order (``--sort gpu``, splatgl/renderers/tile_device.py): tiles
#: touched per thread of the scan (shaders/tile_scan.comp; a block is TILE_SCAN_GROUP times
#: this), and the keys per splat the key buffers first hold (grown, and the frame drawn again,
#: when a frame emits more: the capacity is kept).
TILE_SCAN_ITEMS = 16
TILE_KEYS_PER_SPLAT = 8
#: The alpha every pixel of a device-order frame whose keys overflowed the key buffers gets
#: (shaders/tile_rasterize.comp): never a drawn alpha (1 - T, T in [0, 1]), so the image read
#: back tells the renderer to grow the buffers and draw again, with no status read per frame.
TILE_OVERFLOW_ALPHA = -1.0

#: Compact GPU storage (``--gpu-storage compact``, splatgl/gl/storage.py, shaders/lib/dequantise.glsl):
#: bits of each smallest-three quaternion component and of the linear opacity.  Two components
#: and the 2-bit index fill one uint; the third shares a uint with the opacity.  15 bits, not
#: 10: with 10 the rotation's rounding dominated the image error (81 dB against float32 on the
#: donut at 1280x720, 78 dB on the 150k SH3 synthetic scene); scales are then the largest term.
COMPACT_QUAT_BITS = 15
COMPACT_OPACITY_BITS = 16

#: Early termination's occlusion cull (shaders/occlusion_cull.comp) walks a quad's tiles until
#: it meets an open one; a quad over more tiles than this is kept without the walk.  llvmpipe
#: ends all loops of an invocation after 65535 iterations in total, and an invocation tests 4
#: quads: 4 x 8192 stays below it.  No quad reaches it at 1920 x 1080 (8160 tiles).
OCCLUSION_MAX_TILES = 8192
#: The stop mask's finer level: each 16 x 16 tile holds one bit per block of this many pixels
#: square (4 x 4 blocks of 4 x 4 pixels, bits 0..15), set when all the block's pixels stopped.
#: The occlusion cull tests a quad's pixel range against blocks, not whole tiles: on the shared
#: scenes at 1280x720 this culled 1.2-2.1x as many splats as tiles alone (docs/early-stop.md).
STOP_BLOCK_SIZE = 4
#: ``--early-stop auto`` batches a view only when its quads will rasterise (shaders/coverage.comp)
#: at least EARLY_STOP_MIN_QUAD_FRAGMENTS fragments per drawn quad and EARLY_STOP_MIN_OVERDRAW
#: per image pixel.  The cost model behind it (llvmpipe): batches save shading on the fragments
#: after a pixel's stop, in proportion to fragments, but each batch boundary stops llvmpipe
#: overlapping its single-threaded per-quad work with rasterisation, in proportion to quads.
#: Measured at 1280x720 (docs/early-stop.md, 10 views of 4 scenes): every view at 328-5456
#: fragments per quad ran 1.08-1.43x faster batched, every view at 35-112 ran 0.86-1.01x.  The
#: per-pixel floor is not measured to the point: it keeps views of a few large splats over a
#: mostly empty image (nothing to stop) unbatched, below the 17 per pixel of the least
#: overdrawn view that paid (donut from twice the framing distance, 1.12x).
EARLY_STOP_MIN_QUAD_FRAGMENTS = 200.0
EARLY_STOP_MIN_OVERDRAW = 8.0
#: Batched views of at least this many fragments per quad take the fine schedule
#: (early_stop.FINE_SCHEDULE, about 8 batches), others the coarse one (3 batches).  Larger quads
#: save more shading per batch boundary for the same lost overlap: measured on llvmpipe at
#: 1280x720 (docs/early-stop.md), donut close up at 5456 and 8685 fragments per quad ran 1.70x
#: and 1.89x faster than off with 8 batches against 1.40x and 1.58x with 3; views at 328-1397
#: ran as fast or faster with 3.
EARLY_STOP_FINE_QUAD_FRAGMENTS = 3000.0


def sh_coeff_count(degree: int) -> int:
    """Number of SH coefficients per colour channel for ``degree`` (1, 4, 9 or 16)."""
    return (degree + 1) ** 2


def opacity_extent_sigmas(opacity: float) -> float:
    """Distance, in standard deviations, at which ``opacity * exp(-r^2 / 2)`` reaches ALPHA_MIN.

    Zero when the splat can never reach ALPHA_MIN.
    """
    ratio = opacity / ALPHA_MIN
    return math.sqrt(2.0 * math.log(ratio)) if ratio > 1.0 else 0.0


def glsl_float(value: float) -> str:
    """A GLSL float literal of ``value`` (repr: exact for float64 values)."""
    text = repr(float(value))
    return text if ("e" in text or "." in text) else text + ".0"


def glsl_defines() -> dict[str, str]:
    """The constants above as GLSL ``#define`` values (name -> literal)."""
    out = {
        "TILE_SIZE": str(TILE_SIZE),
        "JACOBIAN_CLAMP": glsl_float(JACOBIAN_CLAMP),
        "LOW_PASS": glsl_float(LOW_PASS),
        "AA_MIN_FACTOR": glsl_float(AA_MIN_FACTOR),
        "EXTENT_DISCRIMINANT_FLOOR": glsl_float(EXTENT_DISCRIMINANT_FLOOR),
        "EXTENT_SIGMAS": glsl_float(EXTENT_SIGMAS),
        "DET_CANCEL_RATIO": glsl_float(DET_CANCEL_RATIO),
        "ALPHA_MAX": glsl_float(ALPHA_MAX),
        "ALPHA_MIN": glsl_float(ALPHA_MIN),
        "T_MIN": glsl_float(T_MIN),
        "MEDIAN_T": glsl_float(MEDIAN_T),
        "SH_OFFSET": glsl_float(SH_OFFSET),
        "SURFEL_FILTER_INV_SQUARE": glsl_float(SURFEL_FILTER_INV_SQUARE),
        "FAST_CORNER_SIGMAS": glsl_float(FAST_CORNER_SIGMAS),
        "PEAK_CLAMP_SIGMAS": glsl_float(PEAK_CLAMP_SIGMAS),
        "FISHEYE_SERIES_RHO": glsl_float(FISHEYE_SERIES_RHO),
        "EQUIRECT_POLE_EPS": glsl_float(EQUIRECT_POLE_EPS),
        "SH_C0": glsl_float(SH_C0),
        "SH_C1": glsl_float(SH_C1),
        "RADIX_BITS": str(RADIX_BITS),
        "RADIX_ITEMS": str(RADIX_ITEMS),
        "RADIX_BLOCK_BITS": str(RADIX_BLOCK_BITS),
        "TILE_SCAN_ITEMS": str(TILE_SCAN_ITEMS),
        "TILE_OVERFLOW_ALPHA": glsl_float(TILE_OVERFLOW_ALPHA),
        "COMPACT_QUAT_BITS": str(COMPACT_QUAT_BITS),
        "COMPACT_OPACITY_BITS": str(COMPACT_OPACITY_BITS),
        "OCCLUSION_MAX_TILES": str(OCCLUSION_MAX_TILES),
        "STOP_BLOCK_SIZE": str(STOP_BLOCK_SIZE),
    }
    for i, c in enumerate(SH_C2):
        out[f"SH_C2_{i}"] = glsl_float(c)
    for i, c in enumerate(SH_C3):
        out[f"SH_C3_{i}"] = glsl_float(c)
    return out
