"""Render settings shared by every path (quad, tile, reference): frozen, with enums for modes."""

from __future__ import annotations

import enum
import numbers
from dataclasses import dataclass

from ..constants import MAX_SH_DEGREE, REFERENCE_NEAR
from ..errors import SplatglError
from .emulation import Emulation
from .transform import SceneTransform  # noqa: F401 (annotation)


class Precision(enum.Enum):
    """Colour target of the quad path's blending."""

    RGBA32F = "rgba32f"
    RGBA16F = "rgba16f"
    RGBA8 = "rgba8"


class QuadExtent(enum.Enum):
    """How the quad path sizes each splat's quad.

    ELLIPSE: along the ellipse axes, out to where ``o exp(-r^2/2)`` reaches 1/255 (default).
    SQUARE: the reference's axis-aligned square of radius ``ceil(3 sqrt(lambda_max))``.
    FAST: the fast approximation of web viewers: a fixed 2 sqrt(2) sigmas along the ellipse
        axes, the fragment evaluating an identity conic on the interpolated corner coordinate.
    """

    ELLIPSE = "ellipse"
    SQUARE = "square"
    FAST = "fast"


class SortKey(enum.Enum):
    """Depth keys of the quad path's sort, and where the quad path and the tile renderer order.

    EXACT: the float32 bits of view z (exact order; ties by index).
    BUCKET16: z quantised into 65536 buckets between the nearest and farthest splat (the
        counting-sort keys some web viewers use; breaks scenes with distant splats).
    GPU: the EXACT keys sorted on the device by a compute-shader radix sort
        (:mod:`splatgl.gl.radix_sort`): the identical order.  On llvmpipe the CPU sort is
        faster (``splatgl bench --scale`` measures both), so EXACT stays this library's
        default; the CLI's ``--sort auto`` takes GPU on a hardware GPU and EXACT on a software
        rasteriser (:func:`splatgl.gl.device_class.resolve_sort`).
        The quad path keeps the whole order on the device where the view's cull is the
        side planes (pinhole, OpenCV; :mod:`splatgl.renderers.quad_device`): cull, keys,
        sort and the draw count in compute shaders, nothing per splat crossing the bus.
        The tile renderer reads EXACT (its CPU order) and GPU (the scan, keys, sort and tile
        ranges on the device, :mod:`splatgl.renderers.tile_device`: the identical image); it
        refuses BUCKET16.
    """

    EXACT = "exact"
    BUCKET16 = "bucket16"
    GPU = "gpu"


class Preprocess(enum.Enum):
    """Where the quad path's per-splat math runs.

    VERTEX: in the vertex shader, once per quad corner (the design card's shape).
    COMPUTE: once per splat in a compute pre-pass; a light vertex shader only places corners.
    """

    VERTEX = "vertex"
    COMPUTE = "compute"


class GpuStorage(enum.Enum):
    """How the quad path (and the tile renderer) store the scene on the GPU.

    Bytes per splat at SH degree 0 / 3 (:func:`splatgl.gl.storage.gpu_bytes_per_splat`):

    FLOAT32: every attribute float32 (64 / 244 B).
    HALF_SH: SH coefficients 1.. as float16 (64 / 154 B).
    COMPACT: means float32; opacity 16-bit; rotation smallest-three, 15 bits a component; scales and
        SH DC float16; SH coefficients 1.. float16 (32 / 122 B).  Error bounds and the measured
        image cost: :mod:`splatgl.gl.storage`, docs/scale.md.
    """

    FLOAT32 = "float32"
    HALF_SH = "half-sh"
    COMPACT = "compact"


class EarlyStop(enum.Enum):
    """Early termination in the quad path (splatgl/renderers/early_stop.py).

    ON: draw the sorted splats in batches; between batches, stop pixels whose transmittance
        fell below the reference's 1e-4 and drop splats that land only on stopped pixels.  The
        schedule (3 batches, or about 8 for views of very large quads) follows the estimate
        below.
    OFF: one plain draw, every fragment shaded.
    AUTO: estimate the fragments the view's quads will rasterise first (their summed area,
        shaders/coverage.comp) and batch only views of large quads over an overdrawn image
        (``constants.EARLY_STOP_MIN_QUAD_FRAGMENTS`` per quad, ``EARLY_STOP_MIN_OVERDRAW`` per
        pixel): elsewhere the batches cost llvmpipe more than the fragments they save.
        That rule is llvmpipe's: on a hardware GPU AUTO draws as ON (measured on one H100,
        :func:`splatgl.gl.device_class.resolve_early_stop`).
    """

    AUTO = "auto"
    ON = "on"
    OFF = "off"


class Convention(enum.Enum):
    """Which published rasterizer's rules the NumPy reference follows (``Compat`` there).

    INRIA: the 3DGS rasterizer (Kerbl et al. 2023), the default and DESIGN.md's reference.
    GSPLAT: gsplat's per-axis opacity-aware extent (up to 3.33 sigma), alpha clamp 0.999, and
    a fisheye's sort key and near test on view z (splatgl's own: the distance).
    """

    INRIA = "inria"
    GSPLAT = "gsplat"


class Order(enum.Enum):
    """The order in which a pixel blends its splats.

    GLOBAL: every pixel of a tile (quad path: of the image) blends the splats in the order of
        their centres' depth (the 3DGS rule; where two splats' Gaussians swap along a ray
        between frames, the result pops).
    PER_PIXEL: each pixel blends its splats sorted by the depth at which each splat's Gaussian
        peaks along that pixel's ray (StopThePop, Radl et al. 2024; a 2DGS surfel: the depth of
        the ray's hit).  The reference sorts each pixel's list exactly; the tile renderer
        re-sorts within a window of ``RenderSettings.order_window`` splats per pixel
        (docs/fidelity.md).  Perspective and orthographic cameras; not the quad path.
    """

    GLOBAL = "global"
    PER_PIXEL = "per-pixel"


#: Splats a pixel of the tile renderer holds back for its per-pixel re-sort (``--order-window``).
#: 32 by measurement (docs/fidelity.md, donut turning in place, 320x180 on llvmpipe): popped
#: pixels 3.0% with a window of 8, 1.3% with 16, 0.24% with 32, against 0.48% for the global order
#: and 0.13% for the reference's exact sort.
DEFAULT_ORDER_WINDOW = 32
#: Largest window: beyond 32 llvmpipe no longer unrolls the window's loops (a window of 64 took
#: 17.6 s a frame, and its loop limit of 65535 iterations cut the loops short).
MAX_ORDER_WINDOW = 32


class RendererKind(enum.Enum):
    """The ``--renderer`` names; what each draws and reads: :mod:`splatgl.renderers.registry`."""

    QUAD = "quad"
    TILE = "tile"
    REFERENCE = "reference"
    #: The reference's per-tile algorithm compiled for the CPU (numba), no OpenGL:
    #: :mod:`splatgl.renderers.cpu`.
    CPU = "cpu"


#: Auto near plane: this fraction of the scene's robust radius, never more than the reference's.
AUTO_NEAR_FRACTION = 0.01


#: The largest background component: float32's largest finite value (the images are float32;
#: a larger one overflowed to inf while compositing, and inf times a zero transmittance is NaN).
MAX_BACKGROUND = 3.4028234663852886e38


@dataclass(frozen=True)
class RenderSettings:
    """What to render and how; the same object drives every renderer.

    Attributes:
        background: RGB composited behind the splats as ``C + (1 - A) bg``.
        precision: blend target of the quad path.
        extent: quad sizing of the quad path.
        near: near-plane distance (view z at or below it is culled); ``None`` picks
            :func:`resolve_near`'s scene-relative default.
        antialias: multiply opacity by the reference's antialiasing compensation factor.
        sh_degree: cap on the SH bands evaluated (``None``: all the scene has).
        transform: where the scene sits in the world (rotation, translation, uniform scale);
            renderers fold it into the camera (:func:`splatgl.cameras.view.apply_transform`).
        sort_key: quad path depth keys.  resort_interval: re-sort every N camera changes
            (1 = always; larger values show sort lag, for the benchmark).
        preprocess: where the quad path's per-splat math runs.  The compute pre-pass is the
            default by measurement (``splatgl bench``, 1280x720 on llvmpipe: 2-13% faster
            on every scene, 13% on a 150k SH3 scene, identical images); surfels always use
            their vertex stage.
        cull: the quad path's CPU frustum/opacity cull (the near plane is always applied).
        gpu_storage: how the scene's attributes are stored on the GPU (:class:`GpuStorage`);
            the benchmark's ``storage`` rows report bytes per splat and the PSNR cost.
        convention: the published rasterizer rules the NumPy reference follows (only the
            reference reads it).
        early_stop: quad path early termination (:class:`EarlyStop`; ``True``/``False`` read as
            ON/OFF).  AUTO by measurement (docs/early-stop.md, 1280x720 on llvmpipe): batching
            ran 1.08-1.43x faster on views of 328-5456 fragments per quad and 0.86-1.01x on
            views of 35-112, so AUTO batches only the former kind.
        emulation: the approximations of other viewers the NumPy reference follows
            (:class:`~splatgl.scene.emulation.Emulation`; only the reference reads it).
        order: :class:`Order`, global (default) or per pixel (the tile renderer and the
            reference).  order_window: splats the tile renderer holds back per pixel for the
            per-pixel re-sort (1..MAX_ORDER_WINDOW; the reference sorts exactly).
    """

    background: tuple[float, float, float] = (0.0, 0.0, 0.0)
    precision: Precision = Precision.RGBA32F
    extent: QuadExtent = QuadExtent.ELLIPSE
    near: float | None = None
    antialias: bool = False
    sh_degree: int | None = None
    transform: "SceneTransform | None" = None
    sort_key: SortKey = SortKey.EXACT
    resort_interval: int = 1
    preprocess: Preprocess = Preprocess.COMPUTE
    cull: bool = True
    gpu_storage: GpuStorage = GpuStorage.FLOAT32
    convention: Convention = Convention.INRIA
    early_stop: EarlyStop = EarlyStop.AUTO
    emulation: Emulation = Emulation()
    order: Order = Order.GLOBAL
    order_window: int = DEFAULT_ORDER_WINDOW

    def __post_init__(self) -> None:
        if isinstance(self.background, (str, bytes)) or not hasattr(self.background, "__len__"):
            raise SettingValueError(f"RenderSettings background: expected 3 numbers (R, G, B), "
                                    f"got {self.background!r}")
        bg = tuple(float(_number(v, "background")) for v in self.background)
        if len(bg) != 3:
            raise SplatglError(f"background must have 3 components, got {len(bg)}")
        if not all(0.0 <= v <= MAX_BACKGROUND for v in bg):   # NaN fails too
            raise SplatglError(f"--background {','.join(f'{v:g}' for v in bg)}: each of R,G,B must "
                               f"be a number from 0 to {MAX_BACKGROUND:.4g} (what a float32 image holds)")
        object.__setattr__(self, "background", bg)
        if isinstance(self.early_stop, bool):
            object.__setattr__(self, "early_stop", EarlyStop.ON if self.early_stop else EarlyStop.OFF)
        for name, kind in ENUM_FIELDS.items():
            object.__setattr__(self, name, _member(kind, getattr(self, name), name))
        if not isinstance(self.emulation, Emulation):
            raise SplatglError(f"emulation must be an Emulation, got {type(self.emulation).__name__}")
        for name in ("order_window", "resort_interval", "near", "sh_degree"):
            if name in ("order_window", "resort_interval") or getattr(self, name) is not None:
                _number(getattr(self, name), name)
        if (int(self.order_window) != self.order_window
                or not 1 <= self.order_window <= MAX_ORDER_WINDOW):
            raise SplatglError(f"order window must be a whole number 1..{MAX_ORDER_WINDOW}, "
                               f"got {self.order_window}")
        if int(self.resort_interval) != self.resort_interval or self.resort_interval < 1:
            raise SplatglError(f"resort interval must be a positive integer, got {self.resort_interval}")
        if self.near is not None and not self.near > 0.0:
            raise SplatglError(f"near plane must be positive, got {self.near}")
        if self.near is not None and not self.near <= MAX_BACKGROUND:
            # every renderer culls z <= near in float32: a larger plane overflowed to inf (a raw
            # NumPy overflow warning) and culled everything; float32's largest is beyond any scene
            raise SplatglError(f"--near {self.near:g}: must be at most {MAX_BACKGROUND:.4g} "
                               "(the largest depth a float32 holds)")
        if self.sh_degree is not None and not 0 <= self.sh_degree <= MAX_SH_DEGREE:
            raise SplatglError(f"SH degree cap must be 0..{MAX_SH_DEGREE}, got {self.sh_degree}")


class SettingValueError(SplatglError, ValueError):
    """A :class:`RenderSettings` mode given as a value its enum does not have (a ValueError, as
    the enum's own refusal was before it named the field)."""


#: RenderSettings' fields that hold an enum member, given as the member or its value.
ENUM_FIELDS = {"precision": Precision, "extent": QuadExtent, "sort_key": SortKey,
               "preprocess": Preprocess, "convention": Convention, "gpu_storage": GpuStorage,
               "early_stop": EarlyStop, "order": Order}


def _number(value, name: str):
    """``value`` where it is a real number (not a bool, not a string); else one line naming the
    field (the checks of its range follow)."""
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise SettingValueError(f"RenderSettings {name}: expected a number, got {value!r}")
    return value


def _member(kind: type[enum.Enum], value, name: str) -> enum.Enum:
    """``value`` (a member of ``kind`` or its value, as ``"rgba16f"``) as the member; else one
    line naming the field, the value and the values accepted."""
    try:
        return kind(value)
    except (ValueError, TypeError):
        accepted = ", ".join(str(m.value) for m in kind)
        raise SettingValueError(f"RenderSettings {name}: {value!r} is not one of {accepted}") from None


def resolve_near(settings: RenderSettings, scene_radius: float) -> float:
    """The near plane to use: the explicit setting, or ``min(0.2, 0.01 * scene_radius)``.

    A fixed 0.2 (the reference's) culls small objects entirely from a camera that frames them
    (the 0.2-unit donut scene); scaling with the scene keeps them while staying the reference's
    value for room-sized scenes.
    """
    if settings.near is not None:
        return float(settings.near)
    radius = scene_radius if scene_radius > 0.0 else 1.0
    return float(min(REFERENCE_NEAR, AUTO_NEAR_FRACTION * radius))
