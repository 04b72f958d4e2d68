"""splatgl: Gaussian-splat rendering through OpenGL's graphics pipeline.

The public API: :func:`load_scene`, :class:`Scene`, :class:`Camera`, :class:`RenderSettings`,
:func:`default_camera`, :func:`render` and :class:`Renderer` (``render_many`` for many views);
:func:`load_cameras` reads every camera source (COLMAP, transforms.json, cameras.json, camera
paths); :mod:`splatgl.paths` generates paths.
"""

from .camera import Camera, Projection, look_at, orbit
from .camera_io import load_camera, save_camera
from .datasets import load_cameras
from .errors import CameraError, ContextError, SceneFormatError, ShaderError, SplatglError
from .formats import load_scene, save_scene
from .render import Renderer, default_camera, render
from .scene import Scene, SplatKind
from .settings import Precision, QuadExtent, RenderSettings, RendererKind

__version__ = "0.1.0"

__all__ = [
    "Camera", "CameraError", "ContextError", "Precision", "Projection", "QuadExtent",
    "RenderSettings", "Renderer", "RendererKind", "Scene", "SceneFormatError", "ShaderError",
    "SplatKind", "SplatglError", "default_camera", "load_camera", "load_cameras", "load_scene",
    "look_at", "orbit", "render", "save_camera", "save_scene",
]
