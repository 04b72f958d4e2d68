"""Large scenes built from real data: jittered, rotated copies of the shared real files.

Synthetic random splats have neither the overlap nor the opacity distribution of trained
scenes (they barely saturate pixels, so early termination and fill costs look nothing like
real ones).  :func:`build_real_scene` tiles copies of real trained scenes side by side on a
horizontal grid instead.  Every copy is normalised to a robust radius of 1, turned about the
vertical axis, scaled by a random factor near 1, and each of its splats is moved by a small
fraction of its own smallest scale, so no two copies are identical while each keeps the
density and overlap of the scene it came from.  The result is deterministic for a seed, and
any ``n_splats`` works (the last copy is a random subset of its source).

Memory: the output arrays are allocated once at their final size and filled copy by copy
(float64 temporaries only per copy), so 6M SH0 splats need about 6M x 60 B = 360 MB plus
the sources.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Sequence

import numpy as np

from ...constants import sh_coeff_count
from ...errors import SplatglError
from ...scene.splats import Scene

#: The shared real files the copies are made from (paths under the shared scenes folder).
REAL_SOURCES = ("ply/donut_sh0.ply", "compressed_ply/biker.compressed.ply",
                "compressed_ply/guitar.compressed.ply")
#: Centre spacing of the copy grid, in copy radii (2 = robust spheres touching; closer, so copies overlap as in a crowded scene).
GRID_SPACING = 1.25
#: Per-copy uniform scale factor range (after normalising to radius 1).
COPY_SCALE_RANGE = (0.85, 1.15)
#: Per-splat position jitter: standard deviation as a fraction of the splat's smallest scale.
POSITION_JITTER = 0.25
#: Per-splat log-scale jitter (standard deviation, natural log units).
LOG_SCALE_JITTER = 0.05


#: The environment variable naming the shared real scenes folder.
SHARED_SCENES_ENV = "SPLATGL_SHARED_SCENES"


def shared_scenes_dir(base: Path | str | None = None) -> Path:
    """The shared real scenes folder: ``$SPLATGL_SHARED_SCENES`` when set, else
    ``../shared/scenes`` relative to ``base`` (default: the current working directory; the
    tests pass the repository root).  The one lookup of the bench, the scale benchmark and the
    tests; the folder may not exist (callers say so, or skip)."""
    env = os.environ.get(SHARED_SCENES_ENV)
    if env:
        return Path(env)
    root = Path.cwd() if base is None else Path(base)
    return Path(os.path.abspath(root)).parent / "shared" / "scenes"


def shared_scenes_help() -> str:
    """Where :func:`shared_scenes_dir` looks, for ``--help`` texts and error messages."""
    return (f"${SHARED_SCENES_ENV} if set, else ../shared/scenes from the working directory "
            f"(here: {shared_scenes_dir()})")


def load_real_sources(names: Sequence[str] = REAL_SOURCES, root: Path | None = None) -> list[Scene]:
    """The shared real scenes ``names`` (paths relative to ``root``, default
    :func:`shared_scenes_dir`); a :class:`SplatglError` names the folder when one is missing."""
    from ...formats import load_scene

    root = shared_scenes_dir() if root is None else Path(root)
    missing = [n for n in names if not (root / n).is_file()]
    if missing:
        raise SplatglError(f"{root / missing[0]}: real scene not found (set {SHARED_SCENES_ENV})")
    return [load_scene(root / n) for n in names]


def _rotate_quats_y(quats: np.ndarray, angle: float) -> np.ndarray:
    """(N, 4) float64: ``r q`` for r the rotation by ``angle`` radians about world y."""
    c, s = np.cos(angle / 2.0), np.sin(angle / 2.0)
    w, x, y, z = (quats[:, i].astype(np.float64) for i in range(4))
    # Hamilton product (c, 0, s, 0) * (w, x, y, z).
    return np.stack([c * w - s * y, c * x + s * z, c * y + s * w, c * z - s * x], axis=1)


def build_real_scene(n_splats: int, seed: int = 0, sh_degree: int | None = None,
                     sources: Sequence[Scene] | None = None) -> Scene:
    """A scene of exactly ``n_splats`` splats made of jittered, rotated copies of real scenes.

    Args:
        n_splats: total splat count (>= 1).
        seed: the result is a pure function of (n_splats, seed, sh_degree, sources).
        sh_degree: SH degree of the result; ``None`` keeps the highest of the sources.  Sources
            below it are zero-padded (their view-independent colour is unchanged), above it
            truncated.  SH bands above 0 are copied unrotated (the view-dependent colour turns
            with the copy's heading; fine for timing, not a faithful rotation).
        sources: scenes to copy, cycled in order; default :func:`load_real_sources` (the
            shared real files: donut, biker, guitar).  All must be of one kind.

    Returns:
        A :class:`Scene` whose copies sit on a square grid in the world x-z plane (y is down,
        the COLMAP convention), ``GRID_SPACING`` copy radii apart, each copy normalised to a
        robust radius of 1 world unit.
    """
    if n_splats < 1:
        raise SplatglError(f"a real-data scene needs at least 1 splat, got {n_splats}")
    sources = list(load_real_sources() if sources is None else sources)
    if not sources:
        raise SplatglError("build_real_scene needs at least one source scene")
    kind = sources[0].kind
    if any(s.kind is not kind for s in sources):
        raise SplatglError("build_real_scene: the source scenes mix 3DGS and 2DGS surfels")
    degree = max(s.sh_degree for s in sources) if sh_degree is None else int(sh_degree)
    k = sh_coeff_count(degree)
    nscale = sources[0].log_scales.shape[1]

    # How many copies, and how many rows of each (the last copy may be partial).
    counts = []
    total = 0
    while total < n_splats:
        take = min(sources[len(counts) % len(sources)].count, n_splats - total)
        counts.append(take)
        total += take
    columns = int(np.ceil(np.sqrt(len(counts))))

    rng = np.random.default_rng(seed)
    means = np.empty((n_splats, 3), np.float32)
    quats = np.empty((n_splats, 4), np.float32)
    log_scales = np.empty((n_splats, nscale), np.float32)
    logits = np.empty(n_splats, np.float32)
    sh = np.zeros((n_splats, k, 3), np.float32)
    start = 0
    for i, take in enumerate(counts):
        src = sources[i % len(sources)]
        rows = (slice(None) if take == src.count
                else np.sort(rng.choice(src.count, take, replace=False)))
        angle = rng.uniform(0.0, 2.0 * np.pi)
        factor = rng.uniform(*COPY_SCALE_RANGE) / max(src.robust_radius, 1e-12)
        lo, hi = src.robust_bounds
        centre = 0.5 * (lo + hi)
        row, col = divmod(i, columns)
        place = GRID_SPACING * np.array([col - (columns - 1) / 2.0, 0.0, row - (columns - 1) / 2.0])

        local = (src.means[rows].astype(np.float64) - centre) * factor
        ls = src.log_scales[rows].astype(np.float64) + np.log(factor)
        ls += rng.normal(0.0, LOG_SCALE_JITTER, ls.shape)
        local += rng.normal(0.0, 1.0, local.shape) * (POSITION_JITTER * np.exp(ls.min(axis=1)))[:, None]
        c, s = np.cos(angle), np.sin(angle)
        x, z = local[:, 0].copy(), local[:, 2]
        local[:, 0] = c * x + s * z      # rotation about +y by ``angle`` (matches the quats)
        local[:, 2] = -s * x + c * z
        end = start + take
        means[start:end] = local + place
        quats[start:end] = _rotate_quats_y(src.quats[rows], angle)
        log_scales[start:end] = ls
        logits[start:end] = src.opacity_logits[rows]
        kk = min(k, src.sh.shape[1])
        sh[start:end, :kk] = src.sh[rows, :kk]
        start = end
    for arr in (means, quats, log_scales, logits, sh):
        arr.flags.writeable = False  # adopted by Scene without a copy
    return Scene(means, quats, log_scales, logits, sh, kind)
