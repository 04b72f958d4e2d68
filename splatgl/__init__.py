"""splatgl: Gaussian-splat rendering through OpenGL's graphics pipeline.

The public API: :func:`load_scene`, :class:`Scene`, :class:`Camera`, :class:`RenderSettings`,
:func:`default_camera`, :func:`render` and :class:`Renderer` (``render_many`` for many views);
:func:`load_cameras` reads every camera source (COLMAP, transforms.json, cameras.json, camera
paths); :mod:`splatgl.paths` generates paths.

The names are imported on first use (PEP 562), so ``import splatgl.cli`` costs only the
standard library and the command line can handle Ctrl-C during its own start-up.
"""

from __future__ import annotations

import importlib
import sys
import types

TYPE_CHECKING = False  # typing.TYPE_CHECKING without importing typing at start-up

__version__ = "0.1.0"

#: Public name -> the submodule defining it.
_EXPORTS = {
    "Camera": "camera", "Projection": "camera", "look_at": "camera", "orbit": "camera",
    "load_camera": "camera_io", "load_cameras": "datasets", "save_camera": "camera_io",
    "CameraError": "errors", "ContextError": "errors", "SceneFormatError": "errors",
    "ShaderError": "errors", "SplatglError": "errors",
    "load_scene": "formats", "save_scene": "formats",
    "Renderer": "render", "default_camera": "render", "render": "render",
    "Scene": "scene", "SplatKind": "scene",
    "Precision": "settings", "QuadExtent": "settings", "RenderSettings": "settings",
    "RendererKind": "settings",
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


class _Package(types.ModuleType):
    """``splatgl.render`` names the function although a submodule has the same name: importing
    the submodule sets the package attribute, which this property ignores."""

    @property
    def render(self):
        from .render import render
        return render

    @render.setter
    def render(self, value) -> None:
        pass  # the import system storing the submodule: keep the function


sys.modules[__name__].__class__ = _Package


if TYPE_CHECKING:  # static analysers see the names directly
    from .camera import Camera, Projection, look_at, orbit
    from .camera_io import load_camera, save_camera
    from .datasets import load_cameras
    from .errors import CameraError, ContextError, SceneFormatError, ShaderError, SplatglError
    from .formats import load_scene, save_scene
    from .render import Renderer, default_camera, render
    from .scene import Scene, SplatKind
    from .settings import Precision, QuadExtent, RenderSettings, RendererKind
