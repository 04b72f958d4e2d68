"""Each renderer's own options: the part of :class:`RenderSettings` it reads.

The user sets one :class:`RenderSettings` (the CLI's options, the API's argument); each renderer
is made with a frozen options object holding only the settings it reads, built in one place:
:func:`splatgl.renderers.registry.options_for`.  The fields are the settings' own, named by
:func:`reads` (their types and defaults stay declared once, in :class:`RenderSettings`), so an
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

from ..scene.emulation import Emulation  # noqa: F401 (the settings' annotations)
from ..scene.settings import (Convention, EarlyStop, GpuStorage, Order,  # noqa: F401 (the same)
                              Precision, Preprocess, QuadExtent, RenderSettings, SortKey)
from ..scene.transform import SceneTransform  # noqa: F401 (annotation)
from ..reference.options import ReferenceOptions

_SETTINGS = {f.name: f for f in dataclasses.fields(RenderSettings)}


def reads(*names: str):
    """Class decorator: a frozen dataclass whose fields (after its base's) are these settings,
    each with the type and default :class:`RenderSettings` declares for it (declared there only)."""
    def make(cls: type) -> type:
        annotations = dict(cls.__dict__.get("__annotations__", {}))
        for name in names:
            setting = _SETTINGS[name]
            annotations[name] = setting.type
            setattr(cls, name, setting.default if setting.default is not dataclasses.MISSING
                    else dataclasses.field(default_factory=setting.default_factory))
        cls.__annotations__ = annotations
        return dataclass(frozen=True)(cls)
    return make


@reads("background", "near", "antialias", "sh_degree", "transform")
class DrawOptions:
    """The settings every renderer reads (:class:`RenderSettings` documents each)."""

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


@reads("precision", "extent", "sort_key", "resort_interval", "preprocess", "cull", "early_stop",
       "gpu_storage")
class QuadOptions(DrawOptions):
    """The quad path's (:class:`splatgl.renderers.quad.QuadRenderer`): its blend target, quad
    sizing, sort, where its per-splat math runs, its CPU cull, early termination and storage."""


@reads("gpu_storage", "sort_key", "order", "order_window")
class TileOptions(DrawOptions):
    """The tile renderer's (:class:`splatgl.renderers.tile.TileRenderer`): storage, where it
    orders (``sort_key``: its CPU order or the device's), the blend order and its window."""


@reads()
class CpuOptions(DrawOptions):
    """The CPU renderer's (:class:`splatgl.renderers.cpu.CpuRenderer`): nothing of its own."""


@reads("convention", "emulation", "order")
class ReferenceRendererOptions(DrawOptions):
    """The NumPy reference's (:class:`splatgl.renderers.reference_renderer.ReferenceRenderer`):
    the published rules, the emulated viewers and the blend order it follows
    (:attr:`reference`: the rasterizer's :class:`~splatgl.reference.options.ReferenceOptions`)."""

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
