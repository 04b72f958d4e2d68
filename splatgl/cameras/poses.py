"""Camera poses: rigid checks that every camera loader shares, and poses that look at a point.

A pose is a (4, 4) float64 world-to-camera matrix in OpenCV axes (+x right, +y down, +z
forward), rigid: a rotation plus a translation, no scale, shear or mirror.
"""

from __future__ import annotations

import math

import numpy as np

from ..constants import RIGID_POSE_TOLERANCE
from ..errors import CameraError


#: The largest magnitude of a camera's numbers (pixels: fx, fy, cx, cy; world units: the pose's
#: entries, look-at points), and the smallest focal length.  The renderers compute in float32,
#: whose squares overflow beyond 1.8e19: larger values leaked NumPy overflow warnings (or an
#: OverflowError) and drew nothing meaningful.  No real camera comes near either bound.
MAX_CAMERA_VALUE = 1e18
MIN_FOCAL = 1e-9


def nonfinite_entry(arr: np.ndarray) -> str | None:
    """'NaN at row 1, column 2' for the first non-finite entry of a 2D array, else None."""
    bad = np.argwhere(~np.isfinite(arr))
    if not len(bad):
        return None
    i, j = (int(v) for v in bad[0])
    return f"{'NaN' if np.isnan(arr[i, j]) else 'Inf'} at row {i}, column {j}"


def rigid_pose_problem(matrix: object, tolerance: float = RIGID_POSE_TOLERANCE) -> str | None:
    """What keeps a camera pose from being a rigid transform, or None when it is one.

    A rigid pose is a rotation (orthonormal rows, determinant +1) plus a translation: no scale,
    shear or mirror.  Camera files must hold one; only :func:`splatgl.cameras.view.apply_transform`
    folds a uniform scale into a camera afterwards.

    Args:
        matrix: (4, 4) world-to-camera (last row must be 0, 0, 0, 1) or (3, 3) rotation, numbers.
        tolerance: largest accepted entry of ``|R R^T - I|`` and ``|det R - 1|``
            (default :data:`splatgl.constants.RIGID_POSE_TOLERANCE`).

    Returns:
        None, or a phrase to follow a field name, e.g. ``"is mirrored (determinant -1)"``,
        ``"holds NaN at row 1, column 2"``.  Every loader uses this one check, so a bad pose
        reads the same whichever file it came from.
    """
    arr = np.asarray(matrix, dtype=np.float64)
    if arr.shape not in ((4, 4), (3, 3)):
        return f"must be a 4x4 or 3x3 matrix, got shape {arr.shape}"
    bad = nonfinite_entry(arr)
    if bad:
        return f"holds {bad}"
    if arr.shape == (4, 4) and not np.allclose(arr[3], [0.0, 0.0, 0.0, 1.0], rtol=0.0, atol=tolerance):
        return f"must have (0, 0, 0, 1) as its last row, got {[float(v) for v in arr[3]]}"
    r = arr[:3, :3]
    det = float(np.linalg.det(r))
    norms = np.linalg.norm(r, axis=1)
    if abs(det) <= tolerance * float(np.prod(norms)):  # Hadamard: |det| <= product of row norms
        return f"is singular (determinant {det:.3g}): not a rotation"
    unit = r / norms[:, None]
    off_diagonal = float(np.abs(unit @ unit.T - np.eye(3)).max())
    if off_diagonal > tolerance:
        return (f"is sheared (its rotation rows are not orthogonal: largest |cos angle| "
                f"{off_diagonal:.3g}, tolerance {tolerance:g}): not a rigid transform")
    if np.abs(norms - 1.0).max() > tolerance:
        lengths = ", ".join(f"{v:.6g}" for v in norms)
        return f"is scaled (its rotation rows have lengths {lengths}, not 1): not a rigid transform"
    if det < 0:
        return f"is mirrored (determinant {det:.6g}, not +1): not a rotation"
    return None


def check_rigid_pose(matrix: object, what: str, tolerance: float = RIGID_POSE_TOLERANCE) -> np.ndarray:
    """``matrix`` as a float64 array if :func:`rigid_pose_problem` finds nothing wrong.

    Raises:
        CameraError: ``"{what} {problem}"``, e.g. ``"cams.json: camera 3: field 'rotation' is
            mirrored (determinant -1, not +1): not a rotation"``.
    """
    problem = rigid_pose_problem(matrix, tolerance)
    if problem:
        raise CameraError(f"{what} {problem}")
    return np.asarray(matrix, dtype=np.float64)


def look_at(eye: np.ndarray, target: np.ndarray, up: np.ndarray = (0.0, -1.0, 0.0)) -> np.ndarray:
    """(4, 4) world-to-camera matrix (OpenCV axes) for a camera at ``eye`` looking at ``target``.

    ``up`` is the world direction that should appear up in the image; the default (0, -1, 0)
    suits scenes trained from COLMAP, whose world y axis usually points down.
    """
    eye = np.asarray(eye, np.float64)
    target = np.asarray(target, np.float64)
    if not np.abs(np.concatenate([eye.ravel(), target.ravel()])).max() <= MAX_CAMERA_VALUE:
        raise CameraError(f"look_at: eye {eye.tolist()} and target {target.tolist()} must lie "
                          f"within {MAX_CAMERA_VALUE:g} of the origin (float32 arithmetic)")
    forward = target - eye
    norm = np.linalg.norm(forward)
    if not norm > 0.0:
        raise CameraError("look_at: eye and target coincide")
    z = forward / norm
    up = np.asarray(up, np.float64)
    x = np.cross(z, up)  # camera y is image-down, about -up; x = y cross z = z cross up
    if np.linalg.norm(x) < 1e-9:
        x = np.cross(z, [1.0, 0.0, 0.0] if abs(z[0]) < 0.9 else [0.0, 0.0, 1.0])
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    m = np.eye(4)
    m[:3, :3] = np.stack([x, y, z])
    m[:3, 3] = -m[:3, :3] @ eye
    return m


def orbit(target: np.ndarray, distance: float, azimuth_degrees: float, elevation_degrees: float,
          up: np.ndarray = (0.0, -1.0, 0.0)) -> np.ndarray:
    """World-to-camera matrix of a camera orbiting ``target`` at ``distance``.

    Azimuth turns about ``up``; elevation lifts the camera towards ``up`` (degrees).
    """
    up = np.asarray(up, np.float64)
    up = up / np.linalg.norm(up)
    # Any unit vector orthogonal to up serves as azimuth 0.
    ref = np.array([0.0, 0.0, 1.0]) if abs(up[2]) < 0.9 else np.array([1.0, 0.0, 0.0])
    a = ref - up * (ref @ up)
    a /= np.linalg.norm(a)
    b = np.cross(up, a)
    az, el = math.radians(azimuth_degrees), math.radians(elevation_degrees)
    direction = math.cos(el) * (math.cos(az) * a + math.sin(az) * b) + math.sin(el) * up
    eye = np.asarray(target, np.float64) + distance * direction
    return look_at(eye, target, up)
