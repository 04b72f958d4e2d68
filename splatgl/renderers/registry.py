"""The renderers by kind: what each one draws, the settings it reads, and making one.

One entry per renderer in :data:`RENDERERS` (as :mod:`splatgl.cameras.registry` has one line per
camera model); everything about drawing a frame lives in the renderer's own module.  This is the
one place that answers "can renderer R draw this request": :func:`refusal` (a view's camera
model, the scene's splats, the layers, geometry under the splats, what must be installed and the
settings' rules) and :func:`check_settings` (options only some renderers read, for the kinds in
play).  The CLI, the API (:class:`splatgl.Renderer`), the viewer and every renderer's own
constructor ask it; no other module keeps a list of what a renderer can draw.

Every renderer follows :class:`~splatgl.renderers.protocol.FrameRenderer`, made with its own
options (:mod:`splatgl.renderers.options`), which :func:`options_for` builds from the user's
:class:`RenderSettings` (the one place a renderer's part of the settings is taken); each is
imported only when first made (:func:`make`): this module loads neither OpenGL nor numba.
"""

from __future__ import annotations

import dataclasses
import enum
import importlib
import importlib.util
from dataclasses import dataclass
from typing import TYPE_CHECKING, Callable, ClassVar

from ..errors import CameraError, SplatglError
from ..gl import limits
from ..scene.splats import Scene, SplatKind
from ..scene.settings import Convention, Order, Precision, RendererKind, RenderSettings, SortKey
from ..output.layers import BASE, Layer
from .options import (DRAWN, CpuOptions, DrawOptions, QuadOptions, ReferenceRendererOptions,
                      TileOptions, own_fields)
from .protocol import FrameRenderer, StageTimes  # noqa: F401 (the interface, named here too)

if TYPE_CHECKING:
    import moderngl

    from ..cameras.model import CameraModel
    from ..cameras.view import View
    from ..gl.shaders import ProgramCache
    from ..output.under import UnderLayer


@dataclass(frozen=True)
class RendererEntry:
    """What one renderer is, and what it draws.

    Attributes:
        kind: its ``--renderer`` name.
        title: how messages name it ("the tile renderer").
        factory: ``"module:Class"`` of its :class:`FrameRenderer`, imported when first made.
        options: its options class (:mod:`splatgl.renderers.options`), whose fields are the
            settings it reads; :attr:`reads`, those beyond the ones every renderer draws
            (:data:`~splatgl.renderers.options.DRAWN`).  A value away from the default of a
            setting no renderer in play reads is refused (:func:`check_settings`).
        gl: whether it draws with OpenGL (made with the context and program cache).
        surfels: whether it draws 2DGS surfel scenes.
        lacks_models: camera model names it cannot draw.
        layers: the layers it draws (None: every one).
        under: whether it composites into geometry under the splats.
        needs: a module that must be importable, and the extra that installs it.
        interactive: whether it draws at a window's pace (the viewer's T steps through these).
        gl_limit: an OpenGL renderer's own image size check beyond the context's side limits
            (:mod:`splatgl.gl.limits`: ``(ctx, width, height, precision) -> why or None``).
        warms_up: whether its first frame costs more than the next (compiling, uploading), so
            that a timed frame follows an untimed one (``compare``, the popping benchmark).
    """

    kind: RendererKind
    title: str
    factory: str
    options: type[DrawOptions] = DrawOptions
    gl: bool = True
    surfels: bool = True
    lacks_models: frozenset[str] = frozenset()
    layers: frozenset[Layer] | None = None
    under: bool = True
    needs: tuple[str, str] | None = None
    interactive: bool = True
    gl_limit: Callable[..., str | None] | None = None
    warms_up: bool = True

    @property
    def reads(self) -> frozenset[str]:
        """The settings it reads beyond :data:`~splatgl.renderers.options.DRAWN`."""
        return own_fields(self.options)

    def renderer_class(self) -> type:
        module, name = self.factory.split(":")
        return getattr(importlib.import_module(module), name)


#: Options some renderers ignore: the setting's field and the option that sets it.
OPTIONS: dict[str, str] = {
    "precision": "--precision", "extent": "--extent", "sort_key": "--sort",
    "resort_interval": "resort interval", "preprocess": "--preprocess", "cull": "cull",
    "early_stop": "--early-stop", "gpu_storage": "--gpu-storage", "convention": "--convention",
    "emulation": "--emulate", "order": "--order", "order_window": "--order-window",
}

#: Every renderer, by kind.  The first is the default.
RENDERERS: dict[RendererKind, RendererEntry] = {e.kind: e for e in (
    RendererEntry(RendererKind.QUAD, "the quad renderer", "splatgl.renderers.quad:QuadRenderer",
                  options=QuadOptions, gl_limit=limits.target_refused),
    RendererEntry(RendererKind.TILE, "the tile renderer", "splatgl.renderers.tile:TileRenderer",
                  options=TileOptions,
                  lacks_models=frozenset({"equirectangular"}),   # it makes no seam copies
                  gl_limit=limits.pixel_buffer_refused),
    RendererEntry(RendererKind.REFERENCE, "the NumPy reference",
                  "splatgl.renderers.reference_renderer:ReferenceRenderer",
                  options=ReferenceRendererOptions, gl=False, interactive=False,
                  warms_up=False),
    RendererEntry(RendererKind.CPU, "the CPU renderer", "splatgl.renderers.cpu:CpuRenderer",
                  options=CpuOptions, gl=False, surfels=False, layers=frozenset(BASE | {Layer.DEPTH}), under=False,
                  needs=("numba", "fast")),
)}


#: The renderer used where none is named (the quad path).
DEFAULT_RENDERER: RendererKind = next(iter(RENDERERS))
STREAMED = (RendererKind.QUAD, RendererKind.CPU)   #: what draws a frame streamed by --memory


def entry(kind: RendererKind | str) -> RendererEntry:
    """The entry of ``kind`` (a :class:`RendererKind` or its name); one line naming the choices
    otherwise."""
    try:
        return RENDERERS[RendererKind(kind)]
    except ValueError:
        choices = ", ".join(f"'{k.value}'" for k in RENDERERS)
        raise SplatglError(f"--renderer must be one of {choices}, got {kind!r}") from None


def names(interactive: bool = False) -> list[str]:
    """The renderer names, default first (``--renderer`` choices); ``interactive``: only those
    that draw at a window's pace (``splatgl view``'s)."""
    return [k.value for k, e in RENDERERS.items() if e.interactive or not interactive]


def image_size_problem(width: int, height: int, kind: RendererKind | str = DEFAULT_RENDERER,
                       ctx=None, precision: Precision | str = Precision.RGBA32F) -> str | None:
    """Why a ``width`` x ``height`` image cannot be rendered here by ``kind``, or None: an
    OpenGL renderer drawing in ``ctx`` is held to the context's side limits and its own
    ``gl_limit`` (the quad path's colour target of ``precision``, the tile renderer's pixel
    buffer); without a context, or for a renderer without OpenGL, :data:`~splatgl.gl.limits.
    MAX_IMAGE_SIDE`; and every renderer to the memory available (:mod:`splatgl.gl.limits`)."""
    e = entry(kind)
    gl = ctx if e.gl else None
    return (limits.side_problem(width, height, gl)
            or (e.gl_limit(gl, width, height, precision)
                if gl is not None and e.gl_limit is not None else None)
            or limits.memory_problem(width, height))


def check_image_size(width: int, height: int, what: str,
                     kind: RendererKind | str = DEFAULT_RENDERER, ctx=None,
                     precision: Precision | str = Precision.RGBA32F) -> None:
    """Raise :class:`SplatglError` ``"{what} {width}x{height} {problem}"`` if the size won't do
    (:func:`image_size_problem`)."""
    problem = image_size_problem(width, height, kind, ctx, precision)
    if problem:
        raise SplatglError(f"{what} {width}x{height} {problem}")


def installed(kind: RendererKind | str) -> bool:
    """Whether what renderer ``kind`` needs is installed (the CPU renderer: numba, ``fast``)."""
    needs = entry(kind).needs
    return needs is None or importlib.util.find_spec(needs[0]) is not None


def make(kind: RendererKind | str, scene: Scene, settings: RenderSettings | DrawOptions,
         ctx: "moderngl.Context | None" = None,
         programs: "ProgramCache | None" = None) -> FrameRenderer:
    """A new renderer of ``kind`` for ``scene`` with its own options (:func:`options_for` of
    ``settings``); an OpenGL one draws in ``ctx``, compiling into ``programs``.  It refuses
    what it cannot draw (:func:`refusal`)."""
    e = entry(kind)
    cls, options = e.renderer_class(), options_for(e.kind, settings)
    if e.gl:
        if ctx is None:
            raise ValueError(f"{e.title} draws with OpenGL: give it a context")
        return cls(ctx, scene, options, programs)
    return cls(scene, options)


def options_for(kind: RendererKind | str, settings: RenderSettings | DrawOptions) -> DrawOptions:
    """Renderer ``kind``'s own options (its entry's ``options`` class) from the user's
    ``settings``: the settings it reads, the others left behind.  Settings it would draw by
    other rules than asked are refused first (:func:`check_fidelity`: the convention, an
    emulation, the per-pixel order, a value only other readers draw); a setting it merely
    ignores is not (:func:`check_settings` refuses those where one renderer is asked for).
    Options of ``kind``'s own class are returned as they are."""
    e = entry(kind)
    if isinstance(settings, e.options):
        return settings
    if not isinstance(settings, RenderSettings):
        raise TypeError(f"{e.title} takes {e.options.__name__} or RenderSettings, "
                        f"not {type(settings).__name__}")
    check_convention(settings.convention, e.kind)
    check_fidelity(settings, e.kind)
    return e.options.of(settings)


def _which(kinds) -> str:
    """``"quad"``, ``"tile or reference"``, ``"quad, reference or cpu"``: the ``--renderer``
    values of ``kinds``, in order."""
    names_ = [k.value for k in RENDERERS if k in kinds]
    return " or ".join(filter(None, (", ".join(names_[:-1]), names_[-1])))


def _renderers(kinds) -> str:
    """``"cpu renderer"``, ``"quad and tile renderers"`` (the reference: "reference")."""
    given = {RendererKind(k) for k in kinds}
    names_ = [k.value for k in RENDERERS if k in given]
    return " and ".join(names_) + (" renderers" if len(names_) > 1 else " renderer")


#: (setting, value) -> the renderers that draw it, where fewer than read the setting.
VALUE_READERS = {("sort_key", SortKey.BUCKET16): frozenset({RendererKind.QUAD})}


def readers(setting: str, value: object = None) -> frozenset[RendererKind]:
    """Who reads ``setting`` (whose options hold it); with ``value``: who draws it."""
    kinds = frozenset(k for k, e in RENDERERS.items() if setting in DRAWN or setting in e.reads)
    return kinds & VALUE_READERS.get((setting, value), kinds)


def honours(kind: RendererKind | str, setting: str) -> bool:
    """Whether renderer ``kind`` reads the setting ``setting`` (:func:`readers`)."""
    return RendererKind(kind) in readers(setting)


def refusal(kind: RendererKind | str, *, scene: Scene | None = None,
            settings: RenderSettings | None = None, model: "CameraModel | None" = None,
            layers: frozenset[Layer] | None = None, under: bool = False) -> str | None:
    """Why renderer ``kind`` cannot draw this request, in one line, or None; what is not given
    is not checked.  :func:`check` raises it."""
    try:
        check(kind, scene=scene, settings=settings, model=model, layers=layers, under=under)
    except SplatglError as exc:
        return str(exc)
    return None


def check(kind: RendererKind | str, *, scene: Scene | None = None,
          settings: RenderSettings | None = None, model: "CameraModel | None" = None,
          layers: frozenset[Layer] | None = None, under: bool = False,
          interactive: bool = False) -> None:
    """Raise :class:`SplatglError` (:class:`CameraError` for a camera model) where renderer
    ``kind`` cannot draw: it is not installed; a scene of surfels; a camera ``model`` (a lens
    model also draws no surfels anywhere); ``layers`` or ``under`` geometry it does not draw;
    ``settings`` whose convention, emulation or order it does not follow (the options it merely
    ignores: :func:`check_settings`); ``interactive``: advice names the viewer's renderers only."""
    e = entry(kind)
    if not installed(e.kind):
        raise SplatglError(f"--renderer {e.kind.value} needs {e.needs[0]}: "
                           f"pip install 'splatgl[{e.needs[1]}]'")
    surfels = scene is not None and scene.kind is SplatKind.SURFEL_2D
    others = [k for k, o in RENDERERS.items() if o.gl and o.surfels]
    if surfels and not e.surfels:
        raise SplatglError(f"--renderer {e.kind.value} draws 3DGS splats; this scene holds 2DGS "
                           f"surfels (use --renderer {_which(others)})")
    if model is not None:
        model.check_surfels(surfels)
        if model.name in e.lacks_models:
            able = [k for k, o in RENDERERS.items() if model.name not in o.lacks_models
                    and (o.interactive or not interactive)]
            raise CameraError(f"{e.title} cannot draw {model.name} images; use --renderer "
                              f"{_which(able)}")
    full = [next(k for k, o in RENDERERS.items() if o.layers is None and o.under)]
    if under and not e.under:
        raise SplatglError(f"--renderer {e.kind.value} cannot composite into --under geometry "
                           f"yet (use --renderer {_which(full)})")
    if layers is not None and e.layers is not None and frozenset(layers) - e.layers:
        names_ = ", ".join(sorted(layer.value for layer in frozenset(layers) - e.layers))
        raise SplatglError(f"--renderer {e.kind.value} draws colour, alpha and depth only, not "
                           f"{names_} (use --renderer {_which(full)})")
    if settings is not None:
        check_convention(settings.convention, e.kind)
        check_fidelity(settings, e.kind)


def check_convention(convention: Convention | str, *kinds: RendererKind | str) -> None:
    """Refuse ``convention`` gsplat unless one of ``kinds`` follows it (the NumPy reference).

    The quad and tile renderers would silently draw the inria rules.  ``splatgl compare``
    passes both of its sides, where a reference on either makes it meaningful (the other
    renderer, drawing the inria rules, measured against the gsplat ones).
    """
    convention = Convention(convention)
    kinds = tuple(RendererKind(k) for k in kinds)
    if convention is Convention.INRIA or readers("convention") & set(kinds):
        return
    names_ = " and ".join(dict.fromkeys(k.value for k in kinds))
    which = f"the {names_} renderers follow" if " and " in names_ else f"the {names_} renderer follows"
    raise SplatglError(f"--convention {convention.value} applies to the NumPy reference only; "
                       f"{which} the inria rules (use --renderer {_which(readers('convention'))})")


def check_fidelity(settings: RenderSettings, *kinds: RendererKind | str) -> None:
    """Refuse an emulation (:mod:`splatgl.scene.emulation`) and the per-pixel order unless one
    of ``kinds`` draws it (:func:`readers`), so that nothing silently draws the plain rules
    where a setting asked for others."""
    kinds = tuple(RendererKind(k) for k in kinds)
    if not settings.emulation.is_default and not readers("emulation") & set(kinds):
        names_ = " and ".join(dict.fromkeys(k.value for k in kinds))
        raise SplatglError(f"--emulate {settings.emulation.label()} applies to the NumPy reference "
                           f"only, not the {names_} renderer (use --renderer "
                           f"{_which(readers('emulation'))})")
    for (name, value), by in VALUE_READERS.items():   # read, but not this value (tile: bucket16)
        if getattr(settings, name) == value and readers(name) & set(kinds) and not by & set(kinds):
            raise SplatglError(f"{OPTIONS[name]} {_spelled(value)} applies to the {_renderers(by)} "
                               f"only, not the {_renderers(kinds)} (use --renderer {_which(by)})")
    by = readers("order")
    if settings.order is Order.PER_PIXEL and not by & set(kinds):
        why = ("; docs/fidelity.md says why the quad path has no per-pixel order"
               if RendererKind.QUAD in kinds else "")
        drawn = " and ".join(RENDERERS[k].title for k in RENDERERS if k in by)
        raise SplatglError(f"--order per-pixel is drawn by {drawn}, not the {_renderers(kinds)} "
                           f"(use --renderer {_which(by)}{why})")


def own_settings(settings: RenderSettings, kind: RendererKind | str) -> RenderSettings:
    """``settings`` as renderer ``kind`` reads them: every setting of :data:`OPTIONS` it does
    not read back at its default (one ``settings`` drawn by several renderers, each its own
    part: ``splatgl compare``'s two sides)."""
    e, default = entry(kind), RenderSettings()
    changes = {name: getattr(default, name) for name in OPTIONS
               if e.kind not in readers(name, getattr(settings, name))
               and getattr(settings, name) != getattr(default, name)}
    return dataclasses.replace(settings, **changes) if changes else settings


def _spelled(value) -> str:
    if isinstance(value, bool):
        return "on" if value else "off"
    return str(value.value if isinstance(value, enum.Enum) else value)


def check_settings(settings: RenderSettings, *kinds: RendererKind | str,
                   advice: str = "use --renderer {which}, or leave {option} out") -> None:
    """Refuse, in one line naming the option, its value and the renderers, a setting away from
    its default that none of ``kinds`` reads (:data:`OPTIONS`, each entry's ``reads``), and
    ``order_window`` without the per-pixel order; the convention, emulation and order as
    :func:`check_convention` and :func:`check_fidelity`.  ``advice`` ends the message
    (``{which}``: the renderers that read the setting, ``{option}``: its option)."""
    kinds = tuple(RendererKind(k) for k in kinds)
    check_convention(settings.convention, *kinds)
    check_fidelity(settings, *kinds)
    default = RenderSettings()
    if settings.order_window != default.order_window and settings.order is not Order.PER_PIXEL:
        raise SplatglError(f"--order-window {settings.order_window} applies to --order per-pixel "
                           "only; the global order has no window (add --order per-pixel)")
    for name, option in OPTIONS.items():
        if name in ("convention", "emulation", "order"):
            continue                                # their own messages, above
        value, by = getattr(settings, name), readers(name, getattr(settings, name))
        if value == getattr(default, name) or by & set(kinds):
            continue
        raise SplatglError(f"{option} {_spelled(value)} applies to the {_renderers(by)} "
                           f"only, not the {_renderers(kinds)}, which would ignore it "
                           f"({advice.format(which=_which(by), option=option)})")


def describe(kind: RendererKind | str, ctx: "moderngl.Context | None") -> str:
    """What drew a frame of ``kind``, as ``--timings`` prints it: the OpenGL renderer's name
    (``ctx``'s; none known without one) for an OpenGL renderer, else what the renderer's module
    says of itself (its ``describe()``)."""
    from ..gl.context import NO_GL_RENDERER, renderer_name

    e = entry(kind)
    if e.gl:
        return NO_GL_RENDERER if ctx is None else renderer_name(ctx)
    return getattr(importlib.import_module(e.factory.split(":")[0]), "describe")()


class Registered:
    """The :class:`FrameRenderer` part every renderer shares: its own options and
    :meth:`supports` (the subclass sets ``kind``, and ``scene`` when made)."""

    kind: ClassVar[RendererKind]

    def own(self, options: DrawOptions | RenderSettings) -> DrawOptions:
        """Set and return :attr:`options`, the renderer's own (:func:`options_for`; the user's
        :class:`RenderSettings` are taken too, as ``CpuRenderer(scene, settings)``)."""
        self.options = options_for(self.kind, options)
        return self.options

    def supports(self, view: "View", layers: frozenset[Layer] = BASE,
                 under: "UnderLayer | None" = None) -> str | None:
        return refusal(self.kind, scene=self.scene, model=view.model,
                       layers=frozenset(layers), under=under is not None)

    def check(self, view: "View", layers: frozenset[Layer] = BASE,
              under: "UnderLayer | None" = None) -> None:
        """Raise what :meth:`supports` says (:func:`check`)."""
        check(self.kind, scene=self.scene, model=view.model, layers=frozenset(layers),
              under=under is not None)
