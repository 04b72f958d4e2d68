"""The level-of-detail tree a budgeted frame draws from, built in the background on first use.

Scenes of at least :data:`LOD_MIN_SPLATS` splats get one: llvmpipe's front end costs about a
microsecond a splat whatever the pixels (donut's 45k splats still took over 100 ms a frame at an
eighth of 1280x720), so the render scale alone cannot keep such a scene within a 100 ms budget.
The tree is built on a daemon thread (:class:`splatgl.background.Background`), so the first
frames draw full detail at a lower scale meanwhile, and is kept in a cache folder
(``$SPLATGL_CACHE``, else ``~/.cache/splatgl``) as ``lod/<key>.lod.ply``, the key naming the
scene file, its size and its modification time: a second session loads it instead of building.
A cache that cannot be written is not an error (the tree is simply rebuilt next time).  A
``.lod.ply`` (from ``splatgl lod``) is its own tree: it is read, never built again or cached.
"""

from __future__ import annotations

import hashlib
import os
from pathlib import Path

from ..background import Background
from ..lod.build import LodTree, build_hierarchy
from ..lod.io import is_lod_file, read_lod, write_lod
from ..scene.splats import Scene, SplatKind

#: Scenes with at least this many splats get a level-of-detail tree for budgeted frames.
LOD_MIN_SPLATS = 20_000
#: Environment variable naming the cache folder.
CACHE_ENV = "SPLATGL_CACHE"


def cache_dir() -> Path:
    """``$SPLATGL_CACHE`` or ``~/.cache/splatgl`` (``$XDG_CACHE_HOME/splatgl`` where set)."""
    env = os.environ.get(CACHE_ENV)
    if env:
        return Path(env)
    base = os.environ.get("XDG_CACHE_HOME")
    return (Path(base) if base else Path.home() / ".cache") / "splatgl"


def cache_file(scene_path: Path) -> Path:
    """Where the tree of the scene file ``scene_path`` is cached (its name, size and mtime)."""
    st = scene_path.stat()
    key = hashlib.sha1(f"{scene_path.resolve()}|{st.st_size}|{st.st_mtime_ns}".encode()).hexdigest()[:16]
    return cache_dir() / "lod" / f"{scene_path.stem}-{key}.lod.ply"


def _load_or_build(scene: Scene, path: Path | None) -> LodTree:
    if path is not None and is_lod_file(path):   # a .lod.ply: its own tree, nothing built
        tree = read_lod(path)                     # or cached (its leaves are the scene's rows)
        if tree.level_size(0) == scene.count:
            return tree
    cached = cache_file(path) if path is not None and path.is_file() else None
    if cached is not None and cached.is_file():
        try:
            tree = read_lod(cached)
            if tree.level_size(0) == scene.count:
                return tree
        except Exception:  # noqa: BLE001 - a damaged cache entry is rebuilt
            pass
    tree = build_hierarchy(scene)
    if cached is not None:
        try:
            cached.parent.mkdir(parents=True, exist_ok=True)
            write_lod(cached, tree)
        except Exception:  # noqa: BLE001 - an unwritable cache only costs the next build
            pass
    return tree


class LodProvider:
    """The tree of ``scene`` (file ``path``, for the cache; None: never cached), built on a
    background thread from construction when the scene is large enough (:data:`LOD_MIN_SPLATS`)
    and holds 3DGS splats (the tree merges 3D Gaussians)."""

    def __init__(self, scene: Scene, path: Path | None = None, min_splats: int = LOD_MIN_SPLATS):
        self.wanted = scene.count >= min_splats and scene.kind is SplatKind.GAUSSIAN_3D
        self._job = Background(_load_or_build, scene, path, name="splatgl-lod-build") if self.wanted else None
        self._tree: LodTree | None = None
        self.error: BaseException | None = None

    @property
    def ready(self) -> bool:
        """Whether the tree can be used now (never blocks)."""
        if self._tree is not None:
            return True
        if self._job is None or not self._job.done():
            return False
        try:
            self._tree = self._job.result()
        except BaseException as exc:  # noqa: BLE001 - budgets then simply stay off
            self.error, self._job = exc, None
            return False
        return True

    @property
    def tree(self) -> LodTree | None:
        return self._tree if self.ready else None

    def wait(self) -> LodTree | None:
        """The tree, waiting for the build (None where the scene gets none)."""
        if self._job is not None and self._tree is None:
            try:
                self._tree = self._job.result()
            except BaseException as exc:  # noqa: BLE001
                self.error, self._job = exc, None
        return self._tree
