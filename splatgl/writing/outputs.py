"""Several output files of one command, written all or nothing.

A command that writes more than one file (``render -o X --depth-png Y``, ``compare
--side-by-side A --heatmap B``, a viewer screenshot and its camera JSON, ``bench --out``)
declares them up front, so bad paths fail before any work:

>>> outputs = OutputFiles({"-o": Path("view.png"), "--depth-png": Path("depth.png")})
>>> ...  # the long work
>>> with outputs:
...     write_image(outputs.temp("-o"), rgba)
...     write_image(outputs.temp("--depth-png"), preview)

Each file is written to a temporary beside its target
(:func:`splatgl.writing.atomic.temp_path`: same folder, so the rename is atomic; same extension,
so writers that pick the format by name still do).  Leaving the ``with`` block
normally renames every temporary onto its target; an exception (a failed write, Ctrl-C,
SIGTERM through :mod:`splatgl.cli`) removes them all, so no output is half-written and none is
written alone.  If a rename itself fails midway (the disk vanished), the files renamed before
it stay complete; none is ever partial.  A failed write inside the block (a
:class:`~splatgl.errors.SplatglError` or an ``OSError``) comes out as one line naming the
target file, never the temporary.

Every command checks its outputs against the files it *reads* too, before any work, with the
same two rules on every command (``inputs``: option name -> path, or several paths for a
folder input such as a dataset's photographs):

>>> OutputFiles({"--json": Path("cam.json")}, inputs={"--camera": Path("cam.json")})
SplatglError: --json cam.json: the same file as --camera; give the output its own name
>>> OutputFiles({"--json": Path("old.json")})          # old.json exists; no overwrite=True
SplatglError: --json old.json: exists (use --force to replace it)

"The same file" is the same absolute path, the same file through a symbolic link (of the file
or of a folder above it) or a hard link (:func:`same_file`); it is refused even with
``overwrite``.  An existing output is replaced only with ``overwrite=True``, which commands
set from their ``--force`` (:func:`splatgl.commands._common.add_force_argument`).  An output
that is a symbolic link is written through to the link's target (the temporary beside the
target, renamed onto it), so the link stays a link.
"""

from __future__ import annotations

import errno
import os
from pathlib import Path
from typing import Iterable, Mapping, Union

from .atomic import AtomicTarget, naming_targets, write_error
from ..errors import SplatglError

#: The errors of a write that found no room (disk full, quota, file size limit).
_FULL = (errno.ENOSPC, errno.EDQUOT, errno.EFBIG)


PathLike = Union[str, Path]
#: A command's inputs: option name (for messages) -> a path, several paths (a folder input such
#: as a dataset's photographs), or None (an option not given).
Inputs = Mapping[str, Union[PathLike, Iterable[PathLike], None]]


def same_file(a: PathLike, b: PathLike) -> bool:
    """Whether paths ``a`` and ``b`` name one file: the same absolute path, the same file
    through symbolic links (the file's or a folder's above it), or hard links to one file."""
    if os.path.abspath(a) == os.path.abspath(b) or os.path.realpath(a) == os.path.realpath(b):
        return True
    try:
        return os.path.samefile(a, b)
    except (OSError, ValueError):  # one does not exist (yet), or cannot be examined
        return False


def _input_paths(inputs: Inputs | None) -> list[tuple[str, Path]]:
    """``inputs`` flattened to (option name, path) pairs, options not given left out."""
    pairs = []
    for name, value in (inputs or {}).items():
        if value is None:
            continue
        for path in [value] if isinstance(value, (str, Path)) else value:
            pairs.append((name, Path(path)))
    return pairs


class InputIndex:
    """A command's inputs indexed by absolute path, real path and inode, so that finding the
    input an output is (:func:`same_file`'s rules) costs the same for thousands of inputs
    (a dataset's photographs) as for one."""

    def __init__(self, inputs: "Inputs | InputIndex | None"):
        if isinstance(inputs, InputIndex):
            self.paths, self.inodes = inputs.paths, inputs.inodes
            return
        self.paths: dict[str, tuple[str, Path]] = {}
        self.inodes: dict[tuple[int, int], tuple[str, Path]] = {}
        for option, path in _input_paths(inputs):
            for key in (os.path.abspath(path), os.path.realpath(path)):
                self.paths.setdefault(key, (option, path))
            inode = _inode(path)
            if inode is not None:
                self.inodes.setdefault(inode, (option, path))

    def find(self, path: PathLike) -> "tuple[str, Path] | None":
        """(option, path) of the input that ``path`` is the same file as, or None."""
        if not self.paths:
            return None
        for key in (os.path.abspath(path), os.path.realpath(path)):
            if key in self.paths:
                return self.paths[key]
        inode = _inode(path)
        return self.inodes.get(inode) if inode is not None else None


def _inode(path: PathLike) -> "tuple[int, int] | None":
    """(device, inode) of an existing file, else None."""
    try:
        st = os.stat(path)
    except (OSError, ValueError):
        return None
    return st.st_dev, st.st_ino


def _pseudo_file_system(folder: Path) -> bool:
    """Whether ``folder`` lies on a file system without storage (/proc, /sys: no blocks)."""
    try:
        return os.statvfs(folder).f_blocks == 0
    except (OSError, AttributeError):  # cannot tell (or no statvfs): the write will say
        return False


def check_not_an_input(path: PathLike, name: str, inputs: "Inputs | InputIndex | None") -> None:
    """Refuse output ``path`` (option ``name``) where it is the same file (:func:`same_file`)
    as one of the command's ``inputs`` (an :class:`InputIndex` to check many outputs against
    many inputs), in one line naming both options."""
    path = Path(path)
    found = (inputs if isinstance(inputs, InputIndex) else InputIndex(inputs)).find(path)
    if found is not None:
        option, source = found
        where = f"{name} {path}" if name else str(path)
        shown = option if os.path.abspath(source) == os.path.abspath(path) else f"{option} {source}"
        raise SplatglError(f"{where}: the same file as {shown}; give the output its own name")


def folder_writable(folder: PathLike) -> bool:
    """Whether files can be made in ``folder``: this user may write and enter it, and its mode
    lets someone write it.  The superuser may write any folder; one whose mode has no write
    bit (``dr-xr-xr-x``, a shared data folder) is still read-only to splatgl (``splatgl lod
    SCENE`` run as root wrote its default output into such a folder beside the scene)."""
    try:
        mode = os.stat(folder).st_mode
    except OSError:
        return False
    return bool(mode & 0o222) and os.access(folder, os.W_OK | os.X_OK)


def check_output_path(path: PathLike, name: str = "", overwrite: bool = False,
                      inputs: "Inputs | InputIndex | None" = None) -> None:
    """Refuse, in one line naming option ``name`` (if any) and ``path``, an output path that
    cannot be written: one of the command's ``inputs`` (see :func:`check_not_an_input`; even
    with ``overwrite``), an existing directory, a folder that does not exist or is not
    writable, an existing file without ``overwrite``.  What every command checks before its
    work.  A symbolic link is checked where it leads (the file written is its target)."""
    path = Path(path)
    where = f"{name} {path}" if name else str(path)
    check_not_an_input(path, name, inputs)
    if path.is_dir():
        raise SplatglError(f"{where}: is a directory; give a file name")
    link = path.is_symlink()  # written through: its target's folder is the one written
    parent = Path(os.path.realpath(path) if link else os.path.abspath(path)).parent
    shown = parent if link else path.parent
    if not parent.is_dir():
        raise SplatglError(f"{where}: folder {shown} does not exist")
    if _pseudo_file_system(parent):
        raise SplatglError(f"{where}: folder {shown} is on a system pseudo file system (such as "
                           "/proc or /sys), where no files can be made; give a folder on a disk")
    if not folder_writable(parent):
        raise SplatglError(f"{where}: folder {shown} is not writable")
    if path.exists() and not overwrite:
        raise SplatglError(f"{where}: exists (use --force to replace it)")


class OutputFiles:
    """Named output paths, checked at construction and committed together.

    Args:
        targets: option name (used in messages, and as the key of :meth:`temp`) -> path; a
            ``None`` path (an option not given) is skipped.
        overwrite: whether an existing file may be replaced (a command's ``--force``;
            directories never are).
        inputs: the files the command reads (option name -> path or paths, see
            :data:`Inputs`): no target may be one of them, ``overwrite`` or not.

    Raises:
        SplatglError: one line naming the option and path: the same file named twice, the same
            file as an input, a path that is an existing directory, a folder that does not
            exist, an existing file without ``overwrite``.
    """

    def __init__(self, targets: dict[str, Path | str | None], overwrite: bool = False,
                 inputs: "Inputs | InputIndex | None" = None):
        self.targets = {name: Path(p) for name, p in targets.items() if p is not None}
        inputs = InputIndex(inputs)
        self._files: dict[str, AtomicTarget] = {}
        seen: list[tuple[Path, str]] = []
        for name, path in self.targets.items():
            for other, other_name in seen:
                if same_file(path, other):
                    raise SplatglError(f"{name} {path}: the same file as {other_name}; give each "
                                       "output its own name")
            seen.append((path, name))
            check_output_path(path, name, overwrite, inputs)

    def temp(self, name: str) -> Path:
        """The temporary to write option ``name``'s file to (inside the ``with`` block)."""
        if name not in self._files:
            self._files[name] = AtomicTarget(self.targets[name])
        return self._files[name].tmp

    def __enter__(self) -> "OutputFiles":
        self._files.clear()
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        try:
            if exc_type is None:
                for name, file in self._files.items():
                    if not file.tmp.exists():
                        raise SplatglError(f"{name} {self.targets[name]}: nothing was written")
                for name, file in list(self._files.items()):
                    file.publish()
                    del self._files[name]
            elif issubclass(exc_type, (SplatglError, OSError)):
                named = self._named(exc)
                if named is not exc:
                    raise named from None
        finally:
            self.discard()

    def _named(self, exc: BaseException) -> BaseException:
        """``exc`` naming the targets where it named their temporaries
        (:func:`~splatgl.writing.atomic.naming_targets`); a full disk's ``OSError`` without a file
        name is laid to the latest file."""
        temps = {file.tmp: file.path for file in self._files.values()}
        if isinstance(exc, OSError) and exc.filename is None and exc.errno in _FULL and temps:
            return write_error(list(temps.values())[-1], exc)  # a write() fails without a name
        return naming_targets(exc, temps)

    def discard(self) -> None:
        """Remove every temporary not yet renamed."""
        for file in self._files.values():
            file.discard()
        self._files.clear()

    @property
    def written(self) -> list[Path]:
        """The target paths, in the order given."""
        return list(self.targets.values())
