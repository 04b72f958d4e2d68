"""Camera paths: splatgl's keyframe path file, smooth interpolation, and generators."""

from .generators import ellipse, focus_point, interpolate, orbit, spiral
from .keyframes import Keyframe, PathFile, parse_path, path_json, write_path

__all__ = ["Keyframe", "PathFile", "ellipse", "focus_point", "interpolate", "orbit", "parse_path",
           "path_json", "spiral", "write_path"]
