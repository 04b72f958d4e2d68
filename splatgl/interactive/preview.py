"""``splatgl render --path ... --preview``: a camera path drawn as the viewer draws a moving camera.

Each camera of the path is one moving frame at the frame-time budget's level (render scale,
splat budget, SH degree: :mod:`.budget`), upscaled to the path's size, so a path can be checked
in a fraction of the exact render's time and looks like what the viewer shows during a flight.
:class:`PreviewRenderer` has the interface :func:`splatgl.tasks.batch.render_frames` renders
with (``render_many``, ``renderer_for``, a context manager); :meth:`PreviewRenderer.report`
says which levels were drawn.
"""

from __future__ import annotations

from collections import Counter
from pathlib import Path
from typing import Iterable, Iterator

from ..api import Renderer
from ..cameras.camera import Camera
from ..errors import SplatglError
from ..scene.splats import Scene, SplatKind
from ..scene.settings import RendererKind, RenderSettings
from ..output.layers import BASE, Layer
from .budget import Level, check_fps
from .lod_cache import LodProvider
from .session import Session, default_fps


#: Levels :meth:`PreviewRenderer.report` lists one by one (the rest in one line).
REPORT_LEVELS = 4


class PreviewRenderer:
    """Draft frames of a path at ``fps`` frames a second (None: the machine's default,
    :func:`~.session.default_fps`) on a headless context of its own; ``scene_path`` locates
    the level-of-detail cache."""

    def __init__(self, fps: float | None = None, scene_path: Path | None = None, progress=print):
        fps = check_fps(fps)
        if fps == 0.0:
            raise SplatglError("--preview needs a frame-time budget: --target-fps must be positive")
        self.renderer = Renderer()
        self.ctx = self.renderer.ctx
        self.fps = fps if fps is not None else default_fps(self.renderer)
        self.scene_path, self.progress = scene_path, progress
        self.levels: Counter[Level] = Counter()
        self.last_times = None    # render_frames sums renderer stage times where there are any

    def render_many(self, scene: Scene, cameras: Iterable[Camera], settings: RenderSettings,
                    kind: RendererKind = RendererKind.QUAD,
                    layers: frozenset[Layer] | None = None) -> Iterator:
        """(H, W, 4) draft frames of ``cameras``, background composited, in order."""
        if RendererKind(kind) is not RendererKind.QUAD:
            raise SplatglError(f"--preview draws through the quad path, not --renderer {kind.value}")
        if layers is not None and set(layers) - BASE:
            names = ", ".join(sorted(layer.value for layer in set(layers) - BASE))
            raise SplatglError(f"--preview draws colour and alpha only, not {names}")
        if scene.kind is not SplatKind.GAUSSIAN_3D:
            raise SplatglError("--preview draws 3DGS scenes (2DGS surfels render through the tile "
                               "renderer, which has no budget)")
        lod = LodProvider(scene, self.scene_path)
        if lod.wanted and self.progress is not None:
            self.progress(f"preview: level-of-detail tree for {scene.count:,} splats ...")
        lod.wait()
        session = Session(self.renderer, scene, settings, 1.0 / self.fps, lod)
        try:
            for camera in cameras:
                frame = session.moving(camera)
                self.levels[frame.level] += 1
                yield session.levels.read(frame)
        finally:
            session.release()

    def renderer_for(self, scene=None, settings=None, kind=None) -> "PreviewRenderer":
        return self

    def report(self) -> str:
        """The levels drawn, most used first: ``scale 0.50, <= 50,000 splats, SH 0: 80 frames``."""
        total = sum(self.levels.values())
        lines = [f"preview at a {1000.0 / self.fps:.0f} ms frame budget ({self.fps:g} fps); "
                 f"draft frames, not the exact render:"]
        common = self.levels.most_common()
        for level, n in common[:REPORT_LEVELS]:
            lines.append(f"  {'exact' if level.exact else level.describe()}: {n} of {total} frames")
        if len(common) > REPORT_LEVELS:
            rest = common[REPORT_LEVELS:]
            scales = [lv.scale for lv, _ in rest]
            lines.append(f"  {len(rest)} other levels (scale {min(scales):.2f}-{max(scales):.2f}): "
                         f"{sum(n for _, n in rest)} frames")
        return "\n".join(lines)

    def close(self) -> None:
        self.renderer.close()

    def __enter__(self) -> "PreviewRenderer":
        return self

    def __exit__(self, *exc) -> None:
        self.close()
