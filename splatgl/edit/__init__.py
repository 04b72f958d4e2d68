"""Scene editing: crop, filter, drop invalid rows, remove floaters, decimate, drop SH bands,
merge scenes (``splatgl edit``), and the statistics that show what a filter would remove
(``splatgl info --stats``).  Every operation the command has is a Python object here:

>>> from splatgl.edit import CropBox, Filter, RemoveFloaters, Decimate, edit_scene
>>> small = edit_scene(scene, CropBox((-1, -1, -1), (1, 1, 1)), Filter("opacity >= 0.02"),
...                    RemoveFloaters(), Decimate(percent=25))

Layer: above the formats, the scene and the LOD merge it reuses; below the commands.
"""

from __future__ import annotations

from ..errors import SplatglError
from ..scene.splats import Scene, require_scene
from .decimate import Decimate
from .expression import Expression, parse_expression
from .files import EditReport, edit_files
from .floaters import RemoveFloaters
from .operations import CropBox, CropSphere, DropInvalid, Filter, ShDegree
from .pipeline import Edited, Step, apply_operations
from .placement import merge_scenes, transform_scene

__all__ = ["CropBox", "CropSphere", "Decimate", "DropInvalid", "EditReport", "Edited",
           "Expression", "Filter", "RemoveFloaters", "ShDegree", "Step", "apply_operations",
           "edit_files", "edit_scene", "merge_scenes", "parse_expression", "transform_scene"]


def edit_scene(scene: Scene, *operations, allow_empty: bool = False, progress=None) -> Scene:
    """``scene`` with ``operations`` applied in order (:func:`apply_operations`); an empty
    result is refused (:class:`SplatglError`) unless ``allow_empty``."""
    require_scene(scene, "edit_scene")
    edited = apply_operations(scene, operations, progress)
    if edited.scene.count == 0 and not allow_empty:
        raise SplatglError("edit: no splats left (pass allow_empty=True to accept an empty "
                           "scene)")
    return edited.scene
