"""The frame-time budget's cost model: what a frame of so many splats and pixels costs on this
device (:class:`CostModel`), learnt from the frames drawn, from a prior by the kind of device."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

#: The cost model's units: splats in 100k, pixels in millions (so its three numbers are of one
#: order, seconds per unit, and the least squares stay well conditioned).
SPLAT_UNIT, PIXEL_UNIT = 1e5, 1e6
#: The cost model's prior (seconds: fixed, per SPLAT_UNIT splats, per PIXEL_UNIT pixels) before
#: any frame is measured, by the kind of device.  A software rasteriser: llvmpipe's (about a
#: microsecond a quad).  A GPU: the H100's quad path (docs/gpu.md: 1M splats at 1280x720 in
#: 74.5 ms, 115 ms at 1920x1080, 6M in 275 ms: about 35 ns a splat with the CPU order and 30 ms a
#: megapixel), rounded up: a safe start that the first frames correct.
SOFTWARE_PRIOR = (0.01, 0.1, 0.05)
HARDWARE_PRIOR = (0.003, 0.005, 0.03)
#: Over its first LEARN_FRAMES measurements the model is rescaled whole wherever a frame took
#: over LEARN_RATIO times (or under 1 / LEARN_RATIO of) its prediction: the device is faster or
#: slower than its prior, on every cost at once as far as one frame can tell (the filter then
#: learns the costs' balance).  Without it the filter put a device 20 times faster's error in the
#: fixed cost of the level it drew, and climbed back to full detail one probe at a time.
LEARN_FRAMES, LEARN_RATIO = 8, 1.5


@dataclass
class CostModel:
    """``t = fixed + per_splat * splats + per_pixel * pixels`` (seconds; ``theta`` per
    :data:`SPLAT_UNIT` splats and :data:`PIXEL_UNIT` pixels), tracked by a Kalman filter from a
    prior (:meth:`for_device`: llvmpipe-like costs by default, 10 ms, 0.1 s per 100k splats,
    50 ms per megapixel), rescaled whole by its first frames where they are far off it
    (:data:`LEARN_FRAMES`).

    Each frame is one measurement with ``noise`` seconds of error; between frames the costs may
    drift by ``drift`` times the prior's widths (the view changes the cost per splat and per
    pixel), so recent frames count most, and a direction frames never probe (frames at one
    level see only one combination of the three) grows uncertain slowly and evenly instead of
    blowing up as least squares with forgetting would.
    """

    noise: float = 0.005
    drift: float = 0.15
    theta: np.ndarray = field(default_factory=lambda: np.array([0.01, 0.1, 0.05]))
    cov: np.ndarray = field(default_factory=lambda: np.diag([0.05, 0.1, 0.1]) ** 2)

    frames: int = 0     # measurements so far

    def __post_init__(self) -> None:
        self._q = np.diag(np.diag(self.cov)) * self.drift ** 2

    @classmethod
    def for_device(cls, software: bool = True) -> "CostModel":
        """The model from :data:`SOFTWARE_PRIOR` or :data:`HARDWARE_PRIOR`, its widths in
        proportion (as the software prior's)."""
        prior = np.array(SOFTWARE_PRIOR if software else HARDWARE_PRIOR)
        widths = np.array([0.05, 0.1, 0.1]) * prior / np.array(SOFTWARE_PRIOR)
        return cls(theta=prior, cov=np.diag(widths) ** 2)

    def _rescale(self, splats: float, pixels: float, seconds: float) -> None:
        """Early on, a frame far off the prediction rescales the whole model (see
        :data:`LEARN_FRAMES`)."""
        predicted = self.predict(splats, pixels)
        self.frames += 1
        if self.frames > LEARN_FRAMES or predicted <= 0.0 or not seconds > 0.0:
            return
        ratio = seconds / predicted
        if 1.0 / LEARN_RATIO <= ratio <= LEARN_RATIO:
            return
        self.theta, self.cov, self._q = self.theta * ratio, self.cov * ratio ** 2, self._q * ratio ** 2

    @staticmethod
    def features(splats: float, pixels: float) -> np.ndarray:
        return np.array([1.0, splats / SPLAT_UNIT, pixels / PIXEL_UNIT])

    def predict(self, splats: float, pixels: float) -> float:
        return max(float(self.theta @ self.features(splats, pixels)), 0.0)

    def update(self, splats: float, pixels: float, seconds: float) -> None:
        self._rescale(splats, pixels, seconds)
        x = self.features(splats, pixels)
        cov = self.cov + self._q                      # the costs drift between frames
        px = cov @ x
        gain = px / (self.noise ** 2 + x @ px)
        self.theta = self.theta + gain * (seconds - x @ self.theta)
        cov = cov - np.outer(gain, px)
        self.cov = 0.5 * (cov + cov.T)
