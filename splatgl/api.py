"""The Python API the CLI is built on: a default camera, and renderers behind one call.

>>> import splatgl
>>> scene = splatgl.load_scene("scene.ply")
>>> camera = splatgl.default_camera(scene, 640, 480)
>>> rgba = splatgl.render(scene, camera)          # (480, 640, 4) float32, row 0 at the top
"""

from __future__ import annotations

import math
from contextlib import contextmanager
from typing import Iterable, Iterator

import moderngl
import numpy as np

from .cameras.camera import Camera
from .cameras.poses import orbit
from .errors import CameraError, SplatglError
from .gl.context import create_headless_context, make_current
from .gl.shaders import ProgramCache
from .gl.limits import check_image_size
from .output.layers import Layer, RenderOutput, with_layers
from .progress import ProgressCallback
from .model.scene import Scene
from .model.settings import RenderSettings, RendererKind
from .cameras.view import View
from .model.transform import ModelTransform

#: Default vertical field of view of :func:`default_camera`, degrees.
DEFAULT_FOV_Y = 50.0
#: Elevation of the default view above the scene's "horizon", degrees.
DEFAULT_ELEVATION = 20.0


def default_camera(scene: Scene, width: int = 1280, height: int = 720,
                   fov_y_degrees: float = DEFAULT_FOV_Y, distance_scale: float = 1.0,
                   model: ModelTransform | None = None, up=(0.0, -1.0, 0.0)) -> Camera:
    """A perspective camera that frames ``scene``.

    Frames the 1st-99th percentile box of the means (so a few stray splats far away do not
    shrink the scene to a dot), from slightly above, with the world direction ``up`` (3,)
    pointing up in the image (default world -y, the COLMAP convention; for a y axis up or down
    it looks along world +z; :func:`splatgl.cameras.up.resolve_up` picks one for a scene), far
    enough that the box's bounding sphere fits the narrower fov, times ``distance_scale``
    (below 1 moves closer).  With a ``model`` transform the scene is framed where the transform
    places it.  Raises :class:`~splatgl.errors.CameraError` for a size that is not a positive
    integer, a field of view outside (0, 180) degrees or a distance scale that is not positive.
    """
    for name, value in (("width", width), ("height", height)):
        if isinstance(value, bool) or int(value) != value or value < 1:
            raise CameraError(f"camera {name} must be a positive integer, got {value!r}")
    if not 0.0 < fov_y_degrees < 180.0:
        raise CameraError(f"field of view must be in (0, 180) degrees, got {fov_y_degrees}")
    if not (math.isfinite(distance_scale) and distance_scale > 0.0):
        raise CameraError(f"distance scale must be a finite number > 0, got {distance_scale}")
    lo, hi = scene.robust_bounds
    centre = 0.5 * (lo + hi)
    radius = max(scene.robust_radius, 1e-6)
    if model is not None:
        centre = model.apply_points(centre[None])[0]
        radius *= model.scale
    fov_y = math.radians(fov_y_degrees)
    fov_x = 2.0 * math.atan(math.tan(fov_y / 2.0) * width / height)
    half = min(fov_x, fov_y) / 2.0
    distance = 1.05 * radius / math.sin(half) * distance_scale
    pose = orbit(centre, distance, 180.0, DEFAULT_ELEVATION, up)
    return Camera.from_fov(width, height, fov_y_degrees, pose)


#: What :meth:`Renderer.render_layers` returns unless asked otherwise.
DEPTH_LAYERS = with_layers(Layer.DEPTH)

#: GPU renderers (each holding an uploaded copy of its scene) kept per :class:`Renderer`; the
#: least recently used is released beyond this.
MAX_CACHED_PATHS = 6


class Renderer:
    """Owns one headless OpenGL context and renders scenes with any renderer kind.

    Per (scene, settings) the GPU state (uploaded scene, programs, targets) is kept, so
    rendering many views of one scene uploads it once.  Use as a context manager or call
    :meth:`close`.
    """

    def __init__(self, ctx: moderngl.Context | None = None):
        self._owns_ctx = ctx is None
        self.ctx = ctx if ctx is not None else create_headless_context()
        self.programs = ProgramCache(self.ctx)
        self._paths: dict[tuple, object] = {}
        self._sizes_ok: set[tuple] = set()
        self.closed = False

    def _check_open(self) -> None:
        if self.closed:
            raise SplatglError("this Renderer is closed (its context was released): render "
                               "inside its 'with' block, or create a new Renderer")

    def _check_size(self, camera: Camera, kind: RendererKind) -> None:
        """Refuse an image the context or the memory cannot hold, before allocating it."""
        key = (camera.width, camera.height, kind)
        if key not in self._sizes_ok:
            check_image_size(camera.width, camera.height, "image", kind, self.ctx)
            self._sizes_ok.add(key)

    def _path(self, scene: Scene, settings: RenderSettings, kind: RendererKind):
        key = (id(scene), settings, kind)
        path = self._paths.pop(key, None)
        if path is not None and path.scene is not scene:  # the id of a scene since collected
            path.release()
            path = None
        if path is None:
            if kind is RendererKind.QUAD:
                from .renderers.quad import QuadRenderer
                path = QuadRenderer(self.ctx, scene, settings, self.programs)
            elif kind is RendererKind.TILE:
                from .renderers.tile import TileRenderer
                path = TileRenderer(self.ctx, scene, settings, self.programs)
            else:
                raise ValueError(f"{kind} has no GPU path")
        self._paths[key] = path  # most recently used last
        while len(self._paths) > MAX_CACHED_PATHS:
            oldest = next(iter(self._paths))
            self._paths.pop(oldest).release()
        return path

    def renderer_for(self, scene: Scene, settings: RenderSettings, kind: RendererKind = RendererKind.QUAD):
        """The (cached) GPU renderer object, e.g. to read its ``last_times``.

        It makes ``self.ctx`` current; when other OpenGL contexts are created later, call
        :func:`splatgl.gl.context.make_current` before using the object directly.
        """
        self._check_open()
        make_current(self.ctx)
        return self._path(scene, settings, kind)

    def render(self, scene: Scene, camera: Camera, settings: RenderSettings = RenderSettings(),
               kind: RendererKind = RendererKind.QUAD, progress: ProgressCallback | None = None) -> np.ndarray:
        """(H, W, 4) float32: RGB = C + (1 - A) background, alpha = A; row 0 is the top.

        ``progress`` (:mod:`splatgl.progress`) hears from the renderers that report it (the
        reference, the tile renderer) during the frame.
        """
        kind = RendererKind(kind)
        self._check_open()
        if kind is RendererKind.REFERENCE:
            return render_reference_rgba(scene, camera, settings, progress)
        make_current(self.ctx)  # another context may have been made current since
        self._check_size(camera, kind)
        with _reporting(self._path(scene, settings, kind), progress) as path:
            return path.render(View.of(camera, settings, scene)).rgba

    def render_layers(self, scene: Scene, camera: Camera, settings: RenderSettings = RenderSettings(),
                      kind: RendererKind = RendererKind.QUAD,
                      progress: ProgressCallback | None = None,
                      layers: frozenset[Layer] = DEPTH_LAYERS) -> RenderOutput:
        """The ``layers`` of one view (default colour, alpha and the accumulated depth; every
        layer from the same pass, with the same weights; :mod:`splatgl.output.layers`)."""
        kind = RendererKind(kind)
        self._check_open()
        if kind is RendererKind.REFERENCE:
            return render_reference_layers(scene, camera, settings, progress)
        make_current(self.ctx)
        self._check_size(camera, kind)
        with _reporting(self._path(scene, settings, kind), progress) as path:
            return path.render(View.of(camera, settings, scene), layers)

    def render_many(self, scene: Scene, cameras: Iterable[Camera],
                    settings: RenderSettings = RenderSettings(),
                    kind: RendererKind = RendererKind.QUAD,
                    layers: frozenset[Layer] | None = None) -> Iterator[np.ndarray | RenderOutput]:
        """Render ``cameras`` one after another, yielding each frame as it is done.

        The scene is uploaded and the shaders compiled once (on the first frame); each frame is
        exactly what :meth:`render` (or :meth:`render_layers` with ``layers``) returns for that
        camera.  Yields (H, W, 4) float32 arrays, or :class:`RenderOutput` with ``layers``.
        """
        for camera in cameras:
            if layers is None:
                yield self.render(scene, camera, settings, kind)
            else:
                yield self.render_layers(scene, camera, settings, kind, layers=layers)

    def close(self) -> None:
        """Release every GPU object and the context (if this Renderer made it); closing twice
        does nothing, rendering afterwards raises :class:`SplatglError`."""
        if self.closed:
            return
        self.closed = True
        make_current(self.ctx)
        for path in self._paths.values():
            path.release()
        self._paths.clear()
        self.programs.release()
        if self._owns_ctx:
            self.ctx.release()

    def __enter__(self) -> "Renderer":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


@contextmanager
def _reporting(path, progress: ProgressCallback | None):
    """``path`` with its ``progress`` attribute set for one frame (renderers without one, as
    the quad path today, simply do not report)."""
    if progress is None or not hasattr(path, "progress"):
        yield path
        return
    path.progress = progress
    try:
        yield path
    finally:
        path.progress = None


def render_reference_rgba(scene: Scene, camera: Camera, settings: RenderSettings,
                          progress: ProgressCallback | None = None) -> np.ndarray:
    """The NumPy per-tile reference as an (H, W, 4) float32 image (no OpenGL)."""
    return render_reference_layers(scene, camera, settings, progress).rgba


def render_reference_layers(scene: Scene, camera: Camera, settings: RenderSettings,
                            progress: ProgressCallback | None = None) -> RenderOutput:
    """The NumPy per-tile reference's colour, alpha and depth (float32 math, no OpenGL)."""
    from .reference import render_reference

    ref = render_reference(scene, camera, settings,
                           compat=settings.convention, progress=progress)
    rgba = np.concatenate([ref.color, ref.alpha[..., None]], axis=-1).astype(np.float32)
    return RenderOutput(rgba, np.asarray(ref.depth, np.float32), DEPTH_LAYERS)


def render(scene: Scene, camera: Camera, settings: RenderSettings = RenderSettings(),
           kind: RendererKind = RendererKind.QUAD) -> np.ndarray:
    """Render one view with a fresh context (use :class:`Renderer` for many views)."""
    if RendererKind(kind) is RendererKind.REFERENCE:
        return render_reference_rgba(scene, camera, settings)
    with Renderer() as r:
        return r.render(scene, camera, settings, kind)
