"""Camera sources and datasets: COLMAP models, NeRF transforms.json, 3DGS cameras.json,
nerfstudio camera paths, splatgl path files; and the train/test split for evaluation.

Each format has one loader module; :mod:`.sources` detects the format by content.
"""

from .sources import load_cameras, load_source, load_views, select_indices
from .named_camera import NamedCamera

__all__ = ["NamedCamera", "load_cameras", "load_source", "load_views", "select_indices"]
