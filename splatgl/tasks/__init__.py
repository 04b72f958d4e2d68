"""Work on more than one process or machine.

The task runner is :mod:`splatgl.tasks.executor` (local processes: :mod:`splatgl.tasks.local`,
``--workers N``; clusters: Ray, :mod:`splatgl.tasks.ray`, ``--executor ray``,
the engine people already use for GPU batch jobs: splatgl writes no scheduler of its own).
The tasks: a camera path's frames (:mod:`.render`), a dataset's views for ``eval``
(:mod:`.evaluate`) and, in :mod:`splatgl.bench.scene_task`, one benchmark scene.
"""
