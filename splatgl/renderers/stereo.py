"""Stereo rigs: left and right eye cameras from one camera, and their images in one frame.

A pinhole, orthographic or fisheye rig places the eyes ``ipd / 2`` either side of the camera
centre along the camera's own x axis (parallel axes, no toe-in).  An equirectangular rig is
omni-directional stereo (ODS): the eye offset rotates with the longitude, per splat
(:func:`splatgl.cameras.equirect.eye_space`), so every direction of the panorama has correct parallax near
the horizon.  Left is the eye at camera -x (image left).
"""

from __future__ import annotations

import enum

import numpy as np

from ..cameras.camera import Camera
from ..errors import CameraError, SplatglError
from ..output.layers import RenderOutput, concat_outputs


class StereoLayout(enum.Enum):
    SIDE_BY_SIDE = "side-by-side"   # left | right, twice the width
    TOP_BOTTOM = "top-bottom"       # left above right, twice the height (the 360-video norm)
    SEPARATE = "separate"           # two files, NAME_left.EXT and NAME_right.EXT


def eye_cameras(camera: Camera, ipd: float) -> tuple[Camera, Camera]:
    """(left, right) cameras of a rig with interpupillary distance ``ipd`` (world units)."""
    if not (np.isfinite(ipd) and ipd > 0.0):
        raise CameraError(f"--stereo needs a positive interpupillary distance, got {ipd}")
    half = 0.5 * float(ipd)
    own = camera.model.eye_pair(camera, half)   # a model's own rig (omni-directional stereo)
    if own is not None:
        return own
    eyes = []
    for offset in (half, -half):           # left eye at camera -x sees points shifted to +x
        shift = np.eye(4)
        shift[0, 3] = offset
        eyes.append(camera.with_pose(shift @ camera.world_to_camera))
    return eyes[0], eyes[1]


def combine(left: RenderOutput, right: RenderOutput, layout: StereoLayout) -> RenderOutput:
    """One frame holding both eyes (side by side or top-bottom); every layer likewise."""
    return concat_outputs(left, right, 1 if StereoLayout(layout) is StereoLayout.SIDE_BY_SIDE else 0)


class StereoRenderer:
    """A :class:`~splatgl.api.Renderer` whose every view is a stereo frame (both eyes in one
    image, ``layout`` side by side or top-bottom): what ``render --path ... --stereo`` renders
    each camera of a path with.  Everything else is delegated to the wrapped renderer."""

    def __init__(self, renderer, ipd: float, layout: StereoLayout):
        if StereoLayout(layout) is StereoLayout.SEPARATE:
            raise CameraError("--stereo-layout separate writes two files per view; for a path use "
                              "side-by-side or top-bottom")
        refusal = getattr(renderer, "stereo_refusal", None)  # e.g. a level-of-detail tree's frames
        if refusal:
            raise SplatglError(refusal)
        eye_cameras(Camera.from_fov(2, 2, 60.0), ipd)  # checks the IPD once, up front
        self._renderer, self.ipd, self.layout = renderer, float(ipd), StereoLayout(layout)

    def __getattr__(self, name):
        return getattr(self._renderer, name)

    def frame_size(self, camera: Camera) -> tuple[int, int]:
        """(width, height) of ``camera``'s stereo frame: twice the width side by side, twice
        the height top-bottom (what a video of these frames is sized by)."""
        if self.layout is StereoLayout.SIDE_BY_SIDE:
            return 2 * camera.width, camera.height
        return camera.width, 2 * camera.height

    def render_layers(self, scene, camera, settings, kind, progress=None, layers=None) -> RenderOutput:
        left, right = (self._renderer.render_layers(scene, eye, settings, kind, progress,
                                                    **({} if layers is None else {"layers": layers}))
                       for eye in eye_cameras(camera, self.ipd))
        return combine(left, right, self.layout)

    def render(self, scene, camera, settings, kind, progress=None) -> np.ndarray:
        left, right = (RenderOutput(self._renderer.render(scene, eye, settings, kind, progress), None)
                       for eye in eye_cameras(camera, self.ipd))
        return combine(left, right, self.layout).rgba

    def render_many(self, scene, cameras, settings, kind, layers=None):
        """Stereo frames of ``cameras``, one after another (as :meth:`Renderer.render_many`)."""
        for camera in cameras:
            if layers is None:
                yield self.render(scene, camera, settings, kind)
            else:
                yield self.render_layers(scene, camera, settings, kind, layers=layers)
