"""Each renderer's own options: the part of :class:`RenderSettings` it reads.

The user sets one :class:`RenderSettings` (the CLI's options, the API's argument); each renderer
is made with a frozen options object holding only the settings it reads, built in one place:
:func:`splatgl.renderers.registry.options_for`.  The field names are the settings' own, so an
options class's fields *are* the declaration of what its renderer reads: the registry derives
from them which renderers read a setting, and refuses a value away from its default that no
renderer in play reads (:func:`~splatgl.renderers.registry.check_settings`).

:class:`DrawOptions` holds what every renderer draws (background, near plane, antialiasing, SH
cap, scene transform); like :class:`RenderSettings` it makes a
:class:`~splatgl.cameras.view.View` (``View.of(camera, options, scene)``).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

from ..scene.emulation import Emulation
from ..scene.settings import (DEFAULT_ORDER_WINDOW, Convention, EarlyStop, GpuStorage, Order,
                              Precision, Preprocess, QuadExtent, RenderSettings, SortKey)
from ..scene.transform import SceneTransform  # noqa: F401 (annotation)
from ..reference.options import ReferenceOptions


@dataclass(frozen=True)
class DrawOptions:
    """The settings every renderer reads (:class:`RenderSettings` documents each)."""

    background: tuple[float, float, float] = (0.0, 0.0, 0.0)
    near: float | None = None
    antialias: bool = False
    sh_degree: int | None = None
    transform: "SceneTransform | None" = None

    def __post_init__(self) -> None:
        # validated and normalised as the settings are ("square" -> QuadExtent.SQUARE)
        checked = self.as_settings()
        for name in field_names(type(self)):
            object.__setattr__(self, name, getattr(checked, name))

    @classmethod
    def of(cls, settings: RenderSettings):
        """This class's part of ``settings`` (validated there)."""
        return cls(**{name: getattr(settings, name) for name in field_names(cls)})

    def as_settings(self) -> RenderSettings:
        """A :class:`RenderSettings` with these values, the others at their defaults."""
        return RenderSettings(**{name: getattr(self, name) for name in field_names(type(self))})


@dataclass(frozen=True)
class QuadOptions(DrawOptions):
    """The quad path's (:class:`splatgl.renderers.quad.QuadRenderer`): its blend target, quad
    sizing, sort, where its per-splat math runs, its CPU cull, early termination and storage."""

    precision: Precision = Precision.RGBA32F
    extent: QuadExtent = QuadExtent.ELLIPSE
    sort_key: SortKey = SortKey.EXACT
    resort_interval: int = 1
    preprocess: Preprocess = Preprocess.COMPUTE
    cull: bool = True
    early_stop: EarlyStop = EarlyStop.AUTO
    gpu_storage: GpuStorage = GpuStorage.FLOAT32


@dataclass(frozen=True)
class TileOptions(DrawOptions):
    """The tile renderer's (:class:`splatgl.renderers.tile.TileRenderer`): storage, where it
    orders (``sort_key``: its CPU order or the device's), the blend order and its window."""

    gpu_storage: GpuStorage = GpuStorage.FLOAT32
    sort_key: SortKey = SortKey.EXACT
    order: Order = Order.GLOBAL
    order_window: int = DEFAULT_ORDER_WINDOW


@dataclass(frozen=True)
class CpuOptions(DrawOptions):
    """The CPU renderer's (:class:`splatgl.renderers.cpu.CpuRenderer`): nothing of its own."""


@dataclass(frozen=True)
class ReferenceRendererOptions(DrawOptions):
    """The NumPy reference's (:class:`splatgl.renderers.reference_renderer.ReferenceRenderer`):
    the published rules, the emulated viewers and the blend order it follows
    (:attr:`reference`: the rasterizer's :class:`~splatgl.reference.options.ReferenceOptions`)."""

    convention: Convention = Convention.INRIA
    emulation: Emulation = Emulation()
    order: Order = Order.GLOBAL

    @property
    def reference(self) -> ReferenceOptions:
        return ReferenceOptions(self.convention, emulation=self.emulation, order=self.order)


def field_names(cls: type) -> tuple[str, ...]:
    """The settings an options class holds, in order."""
    return tuple(f.name for f in dataclasses.fields(cls))


#: The settings every renderer reads (:class:`DrawOptions`).
DRAWN: frozenset[str] = frozenset(field_names(DrawOptions))


def own_fields(cls: type) -> frozenset[str]:
    """The settings an options class reads beyond :data:`DRAWN`: its renderer's own."""
    return frozenset(field_names(cls)) - DRAWN
