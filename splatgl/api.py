"""The Python API the CLI is built on: a default camera, and renderers behind one call.

>>> import splatgl
>>> scene = splatgl.load_scene("scene.ply")
>>> camera = splatgl.default_camera(scene, 640, 480)
>>> rgba = splatgl.render(scene, camera)          # (480, 640, 4) float32, row 0 at the top
"""

from __future__ import annotations

from contextlib import contextmanager
from typing import Iterable, Iterator

import moderngl
import numpy as np

from .cameras.camera import Camera
# the default camera is camera code (the path generators use it too); part of the API
from .cameras.framing import DEFAULT_ELEVATION, DEFAULT_FOV_Y, ORTHOGRAPHIC_SPAN, default_camera  # noqa: F401
from .errors import SplatglError, require
from .gl.context import create_headless_context, make_current
from .gl.shaders import ProgramCache
from .output.layers import BASE, Layer, RenderOutput, with_layers
from .output.under import UnderImage
from .progress import ProgressCallback
from .scene.splats import Scene, SceneSource, require_scene
from .scene.settings import RenderSettings, RendererKind
from .cameras.view import View
from .renderers import registry

#: What a camera argument must be, and how to make one.
CAMERA_NEED = ("a splatgl Camera (splatgl.default_camera(scene, width, height), "
               "splatgl.load_camera(path) or splatgl.Camera.from_fov(...))")


def default_settings(scene: Scene | SceneSource | None = None, **fields) -> RenderSettings:
    """The settings ``splatgl render`` uses for ``scene`` (a loaded scene or its
    :class:`~splatgl.scene.splats.SceneSource`): ``RenderSettings(**fields)``, where
    ``antialias``, unless given (None counts as not given), is on for a file tagged as trained
    with antialiasing (mip-splatting's 2D filter: SPZ's antialiased flag, a PLY
    ``SplatRenderMode: mip`` comment, ...; :func:`splatgl.formats.metadata.antialias_tag`),
    and ``sort_key``, unless given (or given as ``"auto"``), is the device's
    (:func:`splatgl.gl.device_class.resolve_sort`: ``gpu`` on a hardware GPU, ``exact`` on a
    software rasteriser), as ``--sort auto``."""
    from .gl.device_class import AUTO, resolve_sort

    if scene is not None and not isinstance(scene, SceneSource):
        require_scene(scene, "default_settings")
    fields["sort_key"] = resolve_sort(fields.get("sort_key", AUTO))
    source = scene.source if isinstance(scene, Scene) else scene
    if fields.get("antialias") is None:
        fields["antialias"] = source is not None and source.antialias_tag is not None
    return RenderSettings(**fields)


#: What :meth:`Renderer.render_layers` returns unless asked otherwise.
DEPTH_LAYERS = with_layers(Layer.DEPTH)

#: Renderers (each GPU one holding an uploaded copy of its scene) kept per :class:`Renderer`;
#: the least recently used is released beyond this.
MAX_CACHED_PATHS = 6


class Renderer:
    """Owns one headless OpenGL context and renders scenes with any renderer kind (made
    through :mod:`splatgl.renderers.registry`).

    Per (scene, renderer kind, that renderer's own options: :func:`splatgl.renderers.registry.
    options_for`) the renderer and its GPU state (uploaded scene, programs, targets) are kept, so
    rendering many views of one scene uploads it once, and a setting one renderer reads (the
    quad path's ``precision``) makes no other renderer anew.  The context is made when first needed
    (the NumPy reference and the CPU renderer draw without one).  Use as a context manager or
    call :meth:`close`.
    """

    def __init__(self, ctx: moderngl.Context | None = None):
        self._owns_ctx = ctx is None
        self._ctx = ctx
        self._programs: ProgramCache | None = None
        self._paths: dict[tuple, registry.FrameRenderer] = {}
        self._sizes_ok: set[tuple] = set()
        self.closed = False

    @property
    def ctx(self) -> moderngl.Context:
        """The OpenGL context (made on first use)."""
        if self._ctx is None:
            self._check_open()
            self._ctx = create_headless_context()
        return self._ctx

    @property
    def programs(self) -> ProgramCache:
        """The compiled programs of :attr:`ctx`."""
        if self._programs is None:
            self._programs = ProgramCache(self.ctx)
        return self._programs

    def _check_open(self) -> None:
        if self.closed:
            raise SplatglError("this Renderer is closed (its context was released): render "
                               "inside its 'with' block, or create a new Renderer")

    def _check_size(self, camera: Camera, kind: RendererKind, settings: RenderSettings) -> None:
        """Make the context current (every frame: a frame drawn after another context was made
        current, by ``splatgl.render`` or a second Renderer, crashed or came out nearly empty);
        refuse an image the context or the memory cannot hold, before allocating it."""
        gl = self._gl(kind)
        key = (camera.width, camera.height, kind, settings.precision)
        if key not in self._sizes_ok:
            registry.check_image_size(camera.width, camera.height, "image", kind, gl,
                                      settings.precision)
            self._sizes_ok.add(key)

    def _path(self, scene: Scene, settings: RenderSettings,
              kind: RendererKind) -> registry.FrameRenderer:
        options = registry.options_for(kind, settings)   # refuses what it would draw otherwise
        key = (id(scene), kind, options)
        path = self._paths.pop(key, None)
        if path is not None and path.scene is not scene:  # the id of a scene since collected
            path.release()
            path = None
        if path is None:
            gl = self._gl(kind) is not None
            path = registry.make(kind, scene, options, self.ctx if gl else None,
                                 self.programs if gl else None)
        self._paths[key] = path  # most recently used last
        while len(self._paths) > MAX_CACHED_PATHS:
            oldest = next(iter(self._paths))
            self._paths.pop(oldest).release()
        return path

    def _gl(self, kind: RendererKind) -> moderngl.Context | None:
        """The context, made current, where renderer ``kind`` draws with OpenGL; else None."""
        if not registry.entry(kind).gl:
            return None
        make_current(self.ctx)   # another context may have been made current since
        return self.ctx

    def renderer_for(self, scene: Scene, settings: RenderSettings,
                     kind: RendererKind = RendererKind.QUAD) -> registry.FrameRenderer:
        """The (cached) renderer object (:class:`~splatgl.renderers.registry.FrameRenderer`),
        e.g. to read its ``last_times``.

        It makes ``self.ctx`` current; when other OpenGL contexts are created later, call
        :func:`splatgl.gl.context.make_current` before using the object directly.
        """
        require_scene(scene, "Renderer.renderer_for")
        self._check_open()
        kind = registry.entry(kind).kind
        self._gl(kind)
        return self._path(scene, settings, kind)

    def render(self, scene: Scene, camera: Camera | None = None,
               settings: RenderSettings | None = None, kind: RendererKind = RendererKind.QUAD,
               progress: ProgressCallback | None = None) -> np.ndarray:
        """(H, W, 4) float32: RGB = C + (1 - A) background, alpha = A; row 0 is the top.

        ``camera`` None: :func:`default_camera`; ``settings`` None: :func:`default_settings`
        (the scene file's tags decide antialiasing), as ``splatgl render`` without options.
        ``progress`` (:mod:`splatgl.progress`) hears from the renderers that report it (the
        reference, the tile renderer) during the frame.  The quad and tile renderers refuse
        ``convention`` gsplat (:func:`splatgl.renderers.registry.check_convention`).
        """
        require_scene(scene, "Renderer.render")
        return self.render_layers(scene, camera, settings, kind, progress, BASE).rgba

    def render_layers(self, scene: Scene, camera: Camera | None = None,
                      settings: RenderSettings | None = None,
                      kind: RendererKind = RendererKind.QUAD,
                      progress: ProgressCallback | None = None,
                      layers: frozenset[Layer] = DEPTH_LAYERS,
                      under: UnderImage | None = None) -> RenderOutput:
        """The ``layers`` of one view (default colour, alpha and the accumulated depth; every
        layer with the colour's weights, :mod:`splatgl.output.layers`); ``camera`` and
        ``settings`` as in :meth:`render`.  ``under``: geometry rendered from the same camera
        (:func:`splatgl.imagefiles.under_exr.read_under`) to composite the splats into: splats at or
        behind it are dropped, the rest composited over its colour."""
        kind = registry.entry(kind).kind
        camera, settings = _inputs(scene, camera, settings, "Renderer.render_layers")
        if under is not None:
            require(under, UnderImage, "Renderer.render_layers", "under",
                    "an UnderImage (splatgl.imagefiles.under_exr.read_under(path))")
        self._check_open()
        layers = frozenset(layers)
        view = View.of(camera, settings, scene)
        geometry = view.geometry(under) if under is not None else None  # checked before work
        self._check_size(camera, kind, settings)
        with _reporting(self._path(scene, settings, kind), progress) as path:
            if geometry is None:
                return path.render(view, layers)
            return path.render(view, layers, under=geometry)

    def render_many(self, scene: Scene, cameras: Iterable[Camera],
                    settings: RenderSettings | None = None,
                    kind: RendererKind = RendererKind.QUAD,
                    layers: frozenset[Layer] | None = None) -> Iterator[np.ndarray | RenderOutput]:
        """Render ``cameras`` one after another, yielding each frame as it is done.

        The scene is uploaded and the shaders compiled once (on the first frame); each frame is
        exactly what :meth:`render` (or :meth:`render_layers` with ``layers``) returns for that
        camera.  Yields (H, W, 4) float32 arrays, or :class:`RenderOutput` with ``layers``.
        ``settings`` None: :func:`default_settings`.  A bad ``scene`` is refused at the call,
        not at the first frame.
        """
        require_scene(scene, "Renderer.render_many")
        if isinstance(cameras, Camera) or not isinstance(cameras, Iterable):
            require(cameras, (), "Renderer.render_many", "cameras",
                    "an iterable of Cameras (one view: Renderer.render)")
        return self._frames(scene, cameras, settings, kind, layers)

    def _frames(self, scene, cameras, settings, kind, layers) -> Iterator[np.ndarray | RenderOutput]:
        """:meth:`render_many`'s frames."""
        settings = settings if settings is not None else default_settings(scene)
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
        if self._ctx is not None:
            make_current(self._ctx)
        for path in self._paths.values():
            path.release()
        self._paths.clear()
        if self._programs is not None:
            self._programs.release()
        if self._owns_ctx and self._ctx is not None:
            self._ctx.release()

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
    return render_reference_layers(scene, camera, settings, progress, BASE).rgba


def render_reference_layers(scene: Scene, camera: Camera, settings: RenderSettings,
                            progress: ProgressCallback | None = None,
                            layers: frozenset[Layer] = DEPTH_LAYERS,
                            under: UnderImage | None = None) -> RenderOutput:
    """The NumPy per-tile reference's ``layers`` (colour, alpha and depth always; float32
    math, no OpenGL), composited into ``under`` if given (:meth:`Renderer.render_layers`)."""
    with Renderer() as r:
        return r.render_layers(scene, camera, settings, RendererKind.REFERENCE, progress, layers,
                               under)


def gl_renderer_name(kind: RendererKind | str, ctx: moderngl.Context | None) -> str:
    """What drew a frame of ``kind``, as ``--timings`` prints it: the OpenGL renderer's name
    (``ctx``'s), or what stands in for it where no OpenGL draws (the NumPy reference, the CPU
    renderer): :func:`splatgl.renderers.registry.describe`."""
    return registry.describe(kind, ctx)


def _inputs(scene: Scene, camera: Camera | None, settings: RenderSettings | None,
            caller: str) -> tuple[Camera, RenderSettings]:
    """``camera`` and ``settings``, or the scene's defaults where None (``splatgl render``'s);
    a ``scene`` that is none is refused naming ``caller``."""
    require_scene(scene, caller)
    if camera is not None:
        require(camera, Camera, caller, "camera", CAMERA_NEED)
    if settings is not None:
        require(settings, RenderSettings, caller, "settings",
                "a RenderSettings (splatgl.RenderSettings(background=(1, 1, 1), ...) or "
                "splatgl.default_settings(scene, ...))")
    settings = settings if settings is not None else default_settings(scene)
    return camera if camera is not None else default_camera(scene, model=settings.transform), settings


def render(scene: Scene, camera: Camera | None = None, settings: RenderSettings | None = None,
           kind: RendererKind = RendererKind.QUAD) -> np.ndarray:
    """Render one view with a fresh context (use :class:`Renderer` for many views); ``camera``
    and ``settings`` as in :meth:`Renderer.render`.  As ``splatgl render``, a setting ``kind``
    does not read is refused (:func:`splatgl.renderers.registry.check_settings`); a
    :class:`Renderer` draws one ``settings`` with every kind (the viewer's Tab), each reading
    its own part.  No OpenGL context is made for a renderer that needs none."""
    camera, settings = _inputs(scene, camera, settings, "render")
    registry.check_settings(settings, kind)
    with Renderer() as r:
        return r.render(scene, camera, settings, kind)
