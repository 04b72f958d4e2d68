"""Scene file formats: detection from content, and one ``load_scene`` for all of them.

Each format module provides ``NAME`` (str), ``EXTENSIONS`` (tuple of lower-case suffixes),
``sniff(head: bytes) -> bool`` (does the file start like this format?) and
``read(path: Path, drop_invalid: bool) -> Scene`` (optionally also ``progress=None``,
see :mod:`splatgl.progress`).  Writers (the modules in ``_WRITER_MODULES``) provide
``NAME``, ``EXTENSIONS`` and ``write(path, scene)``, which returns None or, for writers that
reorder the splats, the (N,) row order written (``path`` is a temporary,
:func:`splatgl.writing.atomic.temp_path`; a writer whose output depends on the file's name, such
as glTF's ``.gltf`` or SOG's folder form, takes the user's name as ``target=``; one whose
``writes_folder(target)`` holds publishes its several files itself, as a whole, and is handed
the target); lossy writers also provide
``error_bounds(scene) -> dict`` (see :mod:`splatgl.formats.quantise`).
"""

from __future__ import annotations

import dataclasses
import importlib
import inspect
import os
from pathlib import Path
from types import ModuleType

from ..errors import SceneFormatError, require
from ..progress import default_progress
from ..scene.splats import Scene, SceneSource, require_scene
from ._messages import reader_guard

#: Format modules in detection order (most specific signature first).
_FORMAT_MODULES = ("streamed_sog", "lcc", "sog", "gltf", "compressed_ply", "ply", "spz", "ksplat", "splat")
#: Writer modules, most specific extension first (.compressed.ply before .ply).
_WRITER_MODULES = ("compressed_ply_write", "ply_write", "splat", "spz_write", "sog_write", "gltf_write")

#: How many leading bytes ``sniff`` sees.
SNIFF_BYTES = 4096


def _modules(names: tuple[str, ...] = _FORMAT_MODULES) -> list[ModuleType]:
    """The format modules ``names``; a missing one is an error (a broken install), never a
    format silently left out of detection."""
    return [importlib.import_module(f"{__name__}.{name}") for name in names]


def detect_format(path: Path) -> ModuleType:
    """The format module for ``path``: by content first, then by extension."""
    try:
        with open(path, "rb") as fh:
            head = fh.read(SNIFF_BYTES)
    except FileNotFoundError:
        raise SceneFormatError(path, "no such file") from None
    except IsADirectoryError:
        raise SceneFormatError(path, "is a directory, not a scene file") from None
    except OSError as exc:
        raise SceneFormatError(path, f"cannot read: {exc.strerror}") from None
    mods = _modules()
    for mod in mods:
        if mod.sniff(head):
            return mod
    suffix = path.name.lower()
    for mod in mods:
        if any(suffix.endswith(ext) for ext in mod.EXTENSIONS) and not getattr(mod, "NEEDS_MAGIC", False):
            return mod
    names = ", ".join(m.NAME for m in mods)
    raise SceneFormatError(path, f"unknown scene format (supported: {names})")


#: What a scene file argument must be.
PATH_NEED = "a file path (a str or a pathlib.Path)"


def load_scene(path: str | Path, drop_invalid: bool = False, progress=None,
               spz_axes: str | None = None, allow_empty: bool = False) -> Scene:
    """Load a scene file of any supported format.

    Raises :class:`SceneFormatError` (naming file, field and values) for anything malformed.
    With ``drop_invalid``, rows holding NaN/Inf or degenerate quaternions are dropped with a
    warning instead of rejected.  ``progress(done, total, what)`` (see :mod:`splatgl.progress`)
    is handed to readers that read in chunks (those whose ``read`` takes ``progress``); when it
    is None, a stderr meter is used if stderr is a terminal or ``SPLATGL_PROGRESS=1``.
    ``spz_axes`` ("rub" or "rdf"): the axes of an SPZ file that records none (see
    :mod:`splatgl.formats.spz_axes`); refused for other formats.  ``allow_empty``: a PLY or SPZ
    file of zero splats (what ``splatgl edit --allow-empty`` writes) loads as an empty scene,
    for callers that take one (``info``, ``convert``, ``edit``); otherwise it is refused.

    The scene's :attr:`~splatgl.scene.splats.Scene.source` names the file and its tags
    (:func:`scene_source`), which give the scene's default camera up and settings.  A file
    that records a framing box (a ``.lod.ply``'s header, a Streamed SOG manifest ``splatgl lod``
    wrote) is framed by it (:func:`splatgl.formats.metadata.apply_framing_box`).
    """
    path = Path(require(path, (str, os.PathLike), "load_scene", "path", PATH_NEED))
    mod = detect_format(path)
    read = reader_guard(mod.read)  # every format, including any added later
    options = {"drop_invalid": drop_invalid}
    if spz_axes is not None:
        if mod.NAME != "spz":
            raise SceneFormatError(path, f"--spz-axes applies to SPZ files only (this is "
                                         f"{mod.NAME})")
        options["axes"] = spz_axes
    if allow_empty and "allow_empty" in inspect.signature(mod.read).parameters:
        options["allow_empty"] = True
    if "progress" in inspect.signature(mod.read).parameters:
        options["progress"] = progress if progress is not None else default_progress()
    from .metadata import apply_framing_box

    scene = dataclasses.replace(read(path, **options), source=scene_source(path))  # arrays shared
    return apply_framing_box(scene, path)   # a level-of-detail file: its recorded box frames it


def scene_source(path: str | Path) -> SceneSource:
    """What ``path``'s header says about its scene (:class:`SceneSource`), read without loading
    it: whether it is tagged as trained with antialiasing
    (:func:`splatgl.formats.metadata.antialias_tag`)."""
    from .metadata import antialias_tag

    return SceneSource(Path(path), antialias_tag(path))


def writer_for(path: str | Path) -> ModuleType:
    """The format module that writes files named like ``path`` (by extension)."""
    name = Path(path).name.lower()
    if name.endswith("lod-meta.json"):  # not a SOG folder's meta.json: levels of detail
        raise SceneFormatError(path, "a Streamed SOG holds levels of detail: write it with "
                                     "'splatgl lod SCENE -o DIR/lod-meta.json'")
    mods = _modules(_WRITER_MODULES)
    for mod in mods:
        if any(name.endswith(ext) for ext in mod.EXTENSIONS):
            return mod
    exts = ", ".join(ext for mod in mods for ext in mod.EXTENSIONS)
    raise SceneFormatError(path, f"cannot write this format (writable: {exts})")


def stored_bytes(path: str | Path) -> int:
    """Bytes the scene file ``path`` occupies with what it names (a SOG folder's meta.json and
    its textures, a Streamed SOG's units), as its reader's format counts them; else its size."""
    count = getattr(detect_format(Path(path)), "stored_bytes", None)
    return count(Path(path)) if count is not None else Path(path).stat().st_size


def save_scene(path: str | Path, scene: Scene, **options):
    """Write ``scene`` in the format the extension names, atomically (temp file, checked to be
    complete by :func:`splatgl.formats.written.written_problem`, then renamed).

    ``options`` go to the writer (e.g. ``version=2`` for SPZ).  Returns what the writer returns:
    None, or the (N,) row order written when the writer reorders the splats.  A failed or short
    write (a full disk) raises :class:`SplatglError` naming ``path`` and leaves nothing.
    """
    from .written import write_checked

    require(path, (str, os.PathLike), "save_scene", "path", PATH_NEED + " (the scene goes second)")
    require_scene(scene, "save_scene")
    mod = writer_for(path)
    if "target" in inspect.signature(mod.write).parameters:  # its output depends on the name
        options = {**options, "target": Path(path)}
    if getattr(mod, "writes_folder", lambda p: False)(path):  # several files, published whole
        return mod.write(path, scene, **options)
    return write_checked(path, lambda tmp: mod.write(tmp, scene, **options))
