"""splatgl: Gaussian-splat rendering through OpenGL's graphics pipeline.

The public API: :func:`load_scene`, :class:`Scene`, :class:`Camera`, :class:`RenderSettings`,
:func:`default_camera`, :func:`default_settings` (what ``splatgl render`` uses without options),
:func:`render` and :class:`Renderer` (``render_many`` for many views);
:func:`load_cameras` reads every camera source (COLMAP, transforms.json, cameras.json, camera
paths); :mod:`splatgl.paths` generates paths.

The names are imported on first use (PEP 562), so ``import splatgl.cli`` costs only the
standard library and the command line can handle Ctrl-C during its own start-up.
"""

from __future__ import annotations

import importlib

TYPE_CHECKING = False  # typing.TYPE_CHECKING without importing typing at start-up

__version__ = "0.1.0"

#: Public name -> the submodule defining it.
_EXPORTS = {
    "Camera": "cameras.camera", "look_at": "cameras.poses", "orbit": "cameras.poses",
    "Pinhole": "cameras.pinhole", "Orthographic": "cameras.orthographic", "Fisheye": "cameras.fisheye",
    "Equirectangular": "cameras.equirect", "View": "cameras.view",
    "load_camera": "cameras.camera_files", "load_cameras": "datasets", "save_camera": "cameras.camera_files",
    "CameraError": "errors", "ContextError": "errors", "SceneFormatError": "errors",
    "ShaderError": "errors", "SplatglError": "errors",
    "load_scene": "formats", "save_scene": "formats",
    "Renderer": "api", "default_camera": "api", "default_settings": "api", "render": "api",
    "Scene": "scene.splats", "SceneSource": "scene.splats", "SplatKind": "scene.splats",
    "Precision": "scene.settings", "QuadExtent": "scene.settings", "RenderSettings": "scene.settings",
    "RendererKind": "scene.settings",
}

__all__ = sorted(_EXPORTS)


def __getattr__(name: str):
    module = _EXPORTS.get(name)
    if module is None:
        raise AttributeError(f"module 'splatgl' has no attribute {name!r}")
    value = getattr(importlib.import_module(f".{module}", __name__), name)
    globals()[name] = value  # later look-ups skip this function
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_EXPORTS))


if TYPE_CHECKING:  # static analysers see the names directly
    from .cameras.camera import Camera
    from .cameras.equirect import Equirectangular
    from .cameras.fisheye import Fisheye
    from .cameras.orthographic import Orthographic
    from .cameras.pinhole import Pinhole
    from .cameras.poses import look_at, orbit
    from .cameras.view import View
    from .cameras.camera_files import load_camera, save_camera
    from .datasets import load_cameras
    from .errors import CameraError, ContextError, SceneFormatError, ShaderError, SplatglError
    from .formats import load_scene, save_scene
    from .api import Renderer, default_camera, default_settings, render
    from .scene.splats import Scene, SceneSource, SplatKind
    from .scene.settings import Precision, QuadExtent, RenderSettings, RendererKind
