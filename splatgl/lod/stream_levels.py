"""A level of a chunked scene (PlayCanvas Streamed SOG, XGrids LCC) streamed through the same
resident set as a ``.lod.ply`` (issue 41 items 3 and 4).

:class:`LevelChunks` makes the chunks of one level of a structure from
:func:`splatgl.formats.streamed_sog.read_structure` or :func:`splatgl.formats.lcc.read_structure`
the :class:`~splatgl.lod.stream.ResidentSet`'s chunks (a chunk's load decodes only its rows:
``structure.load(level, [chunk], environment=False)``).  :class:`LevelFrames` draws the level
(every chunk, in the file's order, then the environment) with the :class:`splatgl.api.Renderer`:
the image is the whole level's, loaded at once (tests/lod/test_lod_stream.py), and at most the budget
of chunks stays resident between frames.  Not yet: choosing chunks (and coarser levels) by
screen-space error, as the ``.lod.ply`` cut does; a Streamed SOG chunk's load decodes the whole
SOG unit holding it.
"""

from __future__ import annotations

from typing import Iterable, Iterator

from ..cameras.camera import Camera
from ..errors import SplatglError
from ..scene.settings import RendererKind, RenderSettings
from ..output.layers import BASE, Layer, RenderOutput
from ..renderers.registry import DEFAULT_RENDERER
from .budget import format_size
from .stream import LOADERS, ResidentSet, concatenate, scene_bytes


class LevelChunks:
    """The chunks of ``level`` of ``structure`` that hold splats, as resident-set chunks
    (``count``, ``estimate(c)``, ``load(c)``); decoded bytes a row measured on the smallest."""

    rows = 1   # no tree rows: the resident set pins nothing

    def __init__(self, structure, level: int = 0):
        if not 0 <= level < structure.levels:
            raise SplatglError(f"{structure.path}: level {level} does not exist (levels 0-"
                               f"{structure.levels - 1})")
        self.structure, self.level = structure, level
        self.ids = [i for i, c in enumerate(structure.chunks) if c.count(level) > 0]
        self.counts = [structure.chunks[i].count(level) for i in self.ids]
        self.count = len(self.ids)
        self.nodes = sum(self.counts)
        if not self.count:
            raise SplatglError(f"{structure.path}: level {level} holds no splats")
        small = min(range(self.count), key=self.counts.__getitem__)
        self.row_bytes = -(-scene_bytes(self.load(small)) // self.counts[small])

    def estimate(self, chunk: int) -> int:
        return self.counts[chunk] * self.row_bytes

    def load(self, chunk: int):
        return self.structure.load(self.level, [self.ids[chunk]], environment=False)


class LevelFrames:
    """Views of ``level`` of the chunked scene at ``path`` (a ``lod-meta.json`` or ``meta.lcc``)
    through a :class:`ResidentSet` of ``memory`` bytes; ``renderer``: a
    :class:`splatgl.api.Renderer` (the caller's, which it draws with)."""

    def __init__(self, path, renderer, settings: RenderSettings, memory: int, level: int = 0,
                 kind: RendererKind = DEFAULT_RENDERER, threads: int = LOADERS):
        from ..formats import lcc, streamed_sog

        reader = streamed_sog if str(path).lower().endswith("lod-meta.json") else lcc
        self.structure = reader.read_structure(path)
        self.renderer, self.settings, self.kind, self.memory = renderer, settings, kind, int(memory)
        self.chunks = LevelChunks(self.structure, level)
        self.resident = ResidentSet(self.chunks, self.memory, None, 1, threads)
        self._environment = self._load_environment(level)

    def _load_environment(self, level: int):
        """The environment's splats (drawn at every level), or None."""
        try:
            return self.structure.load(level, [], environment=True)
        except SplatglError:   # none: "level holds no splats"
            return None

    def scene(self):
        """The level's splats, waiting for the chunks not resident."""
        parts = self.resident.collect(list(range(self.chunks.count)), lambda c, scene: scene)
        order = [parts[c] for c in range(self.chunks.count)]
        if self._environment is not None:
            order.append(self._environment)
        return concatenate(order)

    def render_view(self, camera: Camera, layers: frozenset[Layer] = BASE) -> RenderOutput:
        scene = self.scene()
        if layers == BASE:
            return RenderOutput(self.renderer.render(scene, camera, self.settings, self.kind), None)
        return self.renderer.render_layers(scene, camera, self.settings, self.kind, None, layers)

    def render_many(self, cameras: Iterable[Camera]) -> Iterator:
        for camera in cameras:
            yield self.render_view(camera).rgba

    def summary(self) -> str:
        return (f"{self.resident.stats.summary(self.memory)}; level {self.chunks.level}: "
                f"{self.chunks.count} chunks, {self.chunks.nodes:,} splats, budget "
                f"{format_size(self.memory)}")

    def close(self) -> None:
        self.resident.close()

    def __enter__(self) -> "LevelFrames":
        return self

    def __exit__(self, *exc) -> None:
        self.close()
