"""``splatgl eval`` on several processes or machines: the dataset's views in contiguous chunks,
each scored by :func:`splatgl.measure.evaluation.evaluate.evaluate` in its own worker, merged back in view order
into the one :class:`~splatgl.measure.evaluation.evaluate.Evaluation` a single process computes (same renders,
same photographs, same scores, so the table, CSV and JSON are identical).

The photographs are read by the workers from their paths: on a cluster the dataset must be on
a file system every node shares (the scene file travels through Ray's object store).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Optional, Sequence

from ...datasets.named_camera import NamedCamera
from .evaluate import Evaluation, Pair, RenderFiles, evaluate
from ...tasks.executor import Executor, ExecutorKind, RunResult, run_tasks
from ...progress import ProgressCallback
from ...tasks.task import Done, Files, TaskProgress
from ...scene.settings import RenderSettings, RendererKind
from ...renderers.registry import DEFAULT_RENDERER
from ...tasks.local import chunks
from ...tasks.ray import MAX_CHUNK_FRAMES


@dataclass(frozen=True)
class EvalChunk:
    """Views ``first ..`` of a dataset: score each; keep the ``keep_worst`` lowest-PSNR pairs."""

    scene_path: Path
    drop_invalid: bool
    views: tuple[NamedCamera, ...]
    first: int
    settings: RenderSettings
    kind: RendererKind
    keep_worst: int
    renders: Optional[RenderFiles] = None

    @property
    def units(self) -> int:
        return len(self.views)

    def inputs(self) -> tuple[Path, ...]:
        return (self.scene_path,)

    def label(self) -> str:
        return f"views {self.first}-{self.first + len(self.views) - 1}"

    def run(self, files: Files, report: TaskProgress) -> Done:
        from ...api import Renderer

        scene = files.load_scene(self.scene_path, self.drop_invalid)
        with Renderer() as renderer:
            result, worst = evaluate(renderer, scene, self.views, self.settings, self.kind,
                                     self.keep_worst, lambda done, total, what: report(done, total),
                                     self.renders)
        return Done((result.scores, worst), len(self.views))


def evaluate_sharded(scene_path: Path, views: Sequence[NamedCamera], executor: Executor,
                     settings: RenderSettings = RenderSettings(), kind: RendererKind = DEFAULT_RENDERER,
                     keep_worst: int = 0, drop_invalid: bool = False,
                     progress: Optional[ProgressCallback] = None,
                     renders: Optional[RenderFiles] = None
                     ) -> tuple[Evaluation, list[Pair], RunResult]:
    """What :func:`splatgl.measure.evaluation.evaluate.evaluate` returns, computed on ``executor`` (local workers:
    one contiguous chunk each; Ray: chunks of at most :data:`MAX_CHUNK_FRAMES` views), and the
    run's per-task reports."""
    n_tasks = (executor.workers if executor.kind is ExecutorKind.LOCAL
               else math.ceil(len(views) / MAX_CHUNK_FRAMES))
    tasks = [EvalChunk(Path(scene_path), drop_invalid, tuple(views[i] for i in part), part.start,
                       settings, RendererKind(kind), keep_worst, renders)
             for part in chunks(len(views), n_tasks)]
    run = run_tasks(tasks, executor, "views", progress)
    scores = tuple(s for chunk_scores, _ in run.values for s in chunk_scores)
    # Each chunk's worst in view order, then a stable sort: the ties fall as in one process.
    pairs = [p for _, worst in run.values for p in worst]
    return Evaluation(scores), sorted(pairs, key=lambda p: p.score.psnr)[:keep_worst], run
