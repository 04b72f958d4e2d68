"""One benchmark scene as a task (:mod:`splatgl.tasks.task`): ``splatgl bench`` over many scenes
measures each scene's rows in its own worker (``--workers N`` or ``--executor ray``) and merges
the rows, in scene order, into one table, bench.csv and bench.json.

Timings from workers that run at the same time on one machine share its cores (and here its
one llvmpipe rasteriser), so they read slower than a lone run's: for fair timings run one
worker per machine (Ray across machines).  The scene file reaches Ray workers through the
object store; synthetic scenes are built in the worker; ``--real-splats`` scenes are built from
the shared real files, which every worker must see.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Optional

from ...tasks.task import Done, Files, TaskProgress
from ...scene.settings import RenderSettings
from ...scene.splats import Scene
from .runner import BenchOptions, BenchRow, Progress, bench_scene

#: Steps a scene reports before its first progress call says how many it has (a guess: the
#: quick rows); the progress line corrects itself from the first report on.
STEPS_GUESS = 8


@dataclass(frozen=True)
class SceneSpec:
    """Which scene to measure: a file (``path``), a synthetic SH3 scene of ``synthetic`` splats,
    or ``real_splats`` splats built from the shared real files.  ``name`` labels its rows."""

    name: str
    path: Path | None = None
    synthetic: int = 0
    real_splats: int = 0

    def inputs(self) -> tuple[Path, ...]:
        return (self.path,) if self.path is not None else ()

    def load(self, files: Files = Files()) -> Scene:
        if self.path is not None:
            from ...formats import load_scene

            with files.local(self.path) as path:
                return load_scene(path)
        if self.synthetic:
            from .synthetic import synthetic_scene

            return synthetic_scene(self.synthetic)
        from .real_scenes import build_real_scene, load_real_sources

        return build_real_scene(self.real_splats, seed=0, sources=load_real_sources())


def measure_scene(renderer, spec: SceneSpec, scene: Scene, options: BenchOptions, savings: bool,
                  progress: Optional[Progress] = None) -> list[BenchRow]:
    """Every row of one scene: the configurations and, with ``savings``, the paired rows, from
    the settings ``splatgl render`` draws with on this device (:func:`default_base`)."""
    from .savings import savings_rows

    base = default_base(renderer.ctx)
    rows = bench_scene(renderer, spec.name, scene, options, base, progress=progress)
    if savings:
        rows += savings_rows(renderer, spec.name, scene, options, base)
    return rows


def default_base(ctx) -> RenderSettings:
    """The default row's settings: the library's defaults with ``--sort auto`` resolved for the
    device ``ctx`` draws on (:func:`splatgl.gl.device_class.resolve_sort`: ``gpu`` on a
    hardware GPU, ``exact`` on a software rasteriser), as ``render`` draws by default
    (``--early-stop auto`` is resolved per device by the quad path itself)."""
    from ...gl.device_class import AUTO, of_context, resolve_sort

    return RenderSettings(sort_key=resolve_sort(AUTO, of_context(ctx)))


@dataclass(frozen=True)
class BenchSceneTask:
    """A worker's share of ``splatgl bench``: one scene's rows, and the worker's machine."""

    spec: SceneSpec
    options: BenchOptions
    savings: bool
    units: int = STEPS_GUESS

    def inputs(self) -> tuple[Path, ...]:
        return self.spec.inputs()

    def label(self) -> str:
        return f"scene {self.spec.name}"

    def run(self, files: Files, report: TaskProgress) -> Done:
        from ...renderers.registry import check_image_size
        from ...api import Renderer
        from ...gl.context import renderer_name
        from .machine import machine_info

        scene = self.spec.load(files)
        with Renderer() as renderer:
            check_image_size(self.options.width, self.options.height, "--width/--height: image",
                             "quad", renderer.ctx)
            machine = machine_info(renderer_name(renderer.ctx), default_row=default_base(renderer.ctx))
            rows = measure_scene(renderer, self.spec, scene, self.options, self.savings,
                                 lambda done, total, what: report(done, total))
        return Done((rows, machine), len(rows))
