"""The benchmark's synthetic scene (``splatgl bench --synthetic N``, one of its scene tasks)."""

from __future__ import annotations

import numpy as np

from ...scene.splats import Scene


def synthetic_scene(n: int = 150_000, degree: int = 3, seed: int = 0) -> Scene:
    """``n`` random splats in a 4-unit box, log-normal scales, SH of ``degree``."""
    rng = np.random.default_rng(seed)
    return Scene(rng.uniform(-2, 2, (n, 3)), rng.normal(size=(n, 4)), rng.normal(-4.0, 0.6, (n, 3)),
                 rng.normal(0.0, 2.0, n), rng.normal(0, 0.3, (n, (degree + 1) ** 2, 3)))
