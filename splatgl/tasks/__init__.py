"""Work on more than one process or machine.

What a task is: :mod:`splatgl.tasks.task`.  The runners build on it (local processes:
:mod:`splatgl.tasks.local`, ``--workers N``; clusters: Ray, :mod:`splatgl.tasks.ray`,
``--executor ray``, the engine people already use for GPU batch jobs: splatgl writes no
scheduler of its own) and :mod:`splatgl.tasks.executor` picks one (``run_tasks``).
The tasks: a camera path's frames (:mod:`.render`), a dataset's views for ``eval``
(:mod:`.evaluate`) and, in :mod:`splatgl.measure.bench.scene_task`, one benchmark scene.
"""
