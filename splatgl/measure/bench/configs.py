"""The benchmark's configurations: one row each, grouped by the question they answer."""

from __future__ import annotations

import dataclasses
import enum
import importlib.util
from dataclasses import dataclass

from ...scene.settings import (EarlyStop, GpuStorage, Precision, Preprocess, QuadExtent,
                              RenderSettings, SortKey)


class RowKind(enum.Enum):
    QUAD = "quad"
    TILE = "tile"
    REFERENCE = "reference"
    CPU = "cpu"
    LIMIT = "limit"


@dataclass(frozen=True)
class BenchConfig:
    """One benchmark row: a renderer and its settings.

    Attributes:
        name: short label, e.g. ``precision=rgba16f``.
        group: the question the row answers (precision, extent, sort, sh, storage, resort, preprocess,
            cull, early-stop, projection, renderer, limit, default).
        kind: which renderer draws it.
        settings: the full settings (the default with one thing changed).
        projection: the camera model the row renders its path with (group ``projection``:
            the orbit's poses and image size through :func:`splatgl.cameras.registry.retarget`);
            None keeps the path's pinhole cameras.
    """

    name: str
    group: str
    kind: RowKind
    settings: RenderSettings
    projection: str | None = None


def configurations(base: RenderSettings, scene_sh_degree: int, quick: bool = False,
                   groups: set[str] | None = None, cpu: bool | None = None) -> list[BenchConfig]:
    """The rows for one scene: the default, each knob changed alone, the other renderers and
    the limit row.  ``quick`` keeps one row per group; ``groups`` filters by group name;
    ``cpu``: a row for the CPU renderer (None: where numba, its extra, is installed)."""

    def q(name: str, group: str, **change) -> BenchConfig:
        return BenchConfig(name, group, RowKind.QUAD, dataclasses.replace(base, **change))

    rows = [BenchConfig("default", "default", RowKind.QUAD, base)]
    rows += [q(f"precision={p.value}", "precision", precision=p)
             for p in Precision if p is not base.precision]
    rows += [q(f"extent={e.value}", "extent", extent=e) for e in QuadExtent if e is not base.extent]
    rows += [q(f"sort={k.value}", "sort", sort_key=k) for k in SortKey if k is not base.sort_key]
    rows += [q(f"sh<={d}", "sh", sh_degree=d) for d in range(scene_sh_degree)]
    rows += [q(f"storage={m.value}", "storage", gpu_storage=m)
             for m in GpuStorage if m is not base.gpu_storage]
    rows += [q(f"resort/{n}", "resort", resort_interval=n) for n in (4, 16)]
    rows += [q(f"preprocess={p.value}", "preprocess", preprocess=p)
             for p in Preprocess if p is not base.preprocess]
    rows.append(q("cull=off", "cull", cull=not base.cull))
    rows += [q(f"early-stop={m.value}", "early-stop", early_stop=m)
             for m in EarlyStop if m is not base.early_stop]
    rows += [BenchConfig(f"projection={p}", "projection", RowKind.QUAD, base, p)
             for p in ("fisheye", "equirectangular")]
    rows.append(BenchConfig("tile", "renderer", RowKind.TILE, base))
    if cpu if cpu is not None else importlib.util.find_spec("numba") is not None:
        rows.append(BenchConfig("cpu", "renderer", RowKind.CPU, base))
    rows.append(BenchConfig("reference", "renderer", RowKind.REFERENCE, base))
    rows.append(BenchConfig("limit", "limit", RowKind.LIMIT, base))
    if quick:
        seen: set[str] = set()
        kept = []
        for row in rows:
            if row.group not in seen or row.group in ("default", "renderer", "limit"):
                kept.append(row)
                seen.add(row.group)
        rows = kept
    if groups:
        rows = [r for r in rows if r.group in groups or r.group in ("default", "limit")]
    return rows
