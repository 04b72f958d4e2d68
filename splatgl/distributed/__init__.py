"""Work on more than one process or machine.

The task runner is :mod:`splatgl.executor` (local processes: :mod:`splatgl.workers`,
``--workers N``; clusters: Ray, :mod:`splatgl.distributed.ray_executor`, ``--executor ray``,
the engine people already use for GPU batch jobs: splatgl writes no scheduler of its own).
The tasks: a camera path's frames (:mod:`.render`), a dataset's views for ``eval``
(:mod:`.evaluate`) and, in :mod:`splatgl.bench.scene_task`, one benchmark scene.
"""
