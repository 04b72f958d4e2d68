"""F12: the current view as ``splatgl render`` writes it, plus the camera that reproduces it."""

from __future__ import annotations

import shlex
from pathlib import Path

from ..cameras.camera import Camera
from ..cameras.camera_files import save_camera
from ..imagefiles.images import write_image
from ..writing.outputs import OutputFiles
from ..api import Renderer
from ..scene.splats import Scene
from ..scene.settings import GpuStorage, RendererKind, RenderSettings
from ..renderers.registry import honours
from ..renderers.stereo import StereoLayout, StereoRenderer

PREFIX = "splatgl-view-"


def next_paths(directory: Path) -> tuple[Path, Path]:
    """The first unused ``splatgl-view-NNNN.png`` / ``.json`` pair in ``directory``."""
    directory.mkdir(parents=True, exist_ok=True)
    n = 1
    while (directory / f"{PREFIX}{n:04d}.png").exists() or (directory / f"{PREFIX}{n:04d}.json").exists():
        n += 1
    return directory / f"{PREFIX}{n:04d}.png", directory / f"{PREFIX}{n:04d}.json"


def settings_arguments(settings: RenderSettings, kind: RendererKind) -> list[str]:
    """``splatgl render`` options giving ``settings`` and ``kind`` (scene transform excluded)."""
    args = ["--renderer", kind.value]
    if honours(kind, "precision"):       # only the options the renderer reads (the CLI refuses
        args += ["--precision", settings.precision.value,      # the others)
                 "--extent", settings.extent.value]
    args += ["--background", ",".join(repr(float(v)) for v in settings.background)]
    if settings.near is not None:
        args += ["--near", repr(settings.near)]
    if settings.antialias:
        args.append("--antialias")
    if settings.sh_degree is not None:
        args += ["--sh-degree", str(settings.sh_degree)]
    if honours(kind, "preprocess"):
        args += ["--preprocess", settings.preprocess.value, "--sort", settings.sort_key.value]
    if settings.gpu_storage is not GpuStorage.FLOAT32 and honours(kind, "gpu_storage"):
        args += ["--gpu-storage", settings.gpu_storage.value]
    return args


def save_screenshot(renderer: Renderer, scene: Scene, camera: Camera, settings: RenderSettings,
                    kind: RendererKind, directory: Path, render_args=(),
                    stereo: float | None = None) -> tuple[Path, Path, str]:
    """Write the 8-bit PNG of ``camera``'s view (the renderer call and :func:`write_image` of
    ``splatgl render``) and the camera JSON; returns (png, json, reproducing command line).
    With ``stereo`` (an IPD), the PNG holds both eyes of ``camera`` side by side, as
    ``splatgl render --stereo IPD`` writes it."""
    png, js = next_paths(Path(directory))
    if stereo is not None:
        renderer = StereoRenderer(renderer, stereo, StereoLayout.SIDE_BY_SIDE)
    rgba = renderer.render(scene, camera, settings, kind)
    files = OutputFiles({"image": png, "camera": js}, overwrite=False)
    with files:  # both or neither
        save_camera(files.temp("camera"), camera)
        write_image(files.temp("image"), rgba)
    argv = ["splatgl", "render", *render_args, "--camera", str(js), *settings_arguments(settings, kind),
            *(["--stereo", repr(float(stereo))] if stereo is not None else []), "-o", str(png)]
    return png, js, shlex.join(argv)


def take_screenshot(viewer) -> tuple[Path, Path]:
    """In ``viewer`` (:class:`~.app.Viewer`): write what ``splatgl render`` writes from the
    current camera, and that camera (:func:`save_screenshot`: the exact render, whatever draft the
    window shows); in stereo, both eyes side by side (``--stereo``) from the camera of one eye's
    half.  Says so on the status line and prints the command that reproduces it."""
    import glfw

    from . import controls

    v = viewer
    glfw.make_context_current(v.window)
    camera = v.camera()
    if v.options.stereo is not None:
        camera = controls.fit_camera(camera, max(camera.width // 2, 1), camera.height)
    png, js, command = save_screenshot(v.renderer, v.scene_now(camera, exact=True), camera,
                                       v.settings, v.kind,
                                       v.options.screenshot_dir, v.options.render_args,
                                       v.options.stereo)
    v.message = f"saved {png.name} + {js.name} (exact render)"
    print(f"wrote {png} and {js}; reproduce with:\n  {command}", flush=True)
    v.need_present = True
    return png, js
