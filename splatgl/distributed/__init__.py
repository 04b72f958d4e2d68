"""Rendering frame lists on more than one process or machine.

Local processes are :mod:`splatgl.workers` (``--workers N``); clusters run on Ray
(:mod:`splatgl.distributed.ray_executor`, ``--executor ray``), the engine people already use
for GPU batch jobs: splatgl writes no scheduler of its own.
"""
