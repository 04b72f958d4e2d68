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
(:func:`splatgl.output.atomic.temp_path`: same folder, so the rename is atomic; same extension,
so writers that pick the format by name still do).  Leaving the ``with`` block
normally renames every temporary onto its target; an exception (a failed write, Ctrl-C,
SIGTERM through :mod:`splatgl.cli`) removes them all, so no output is half-written and none is
written alone.  If a rename itself fails midway (the disk vanished), the files renamed before
it stay complete; none is ever partial.  A failed write inside the block (a
:class:`~splatgl.errors.SplatglError` or an ``OSError``) comes out as one line naming the
target file, never the temporary.
"""

from __future__ import annotations

import errno
import os
from pathlib import Path

from .atomic import AtomicTarget, naming_targets, write_error
from ..errors import SplatglError

#: The errors of a write that found no room (disk full, quota, file size limit).
_FULL = (errno.ENOSPC, errno.EDQUOT, errno.EFBIG)


def check_output_path(path: str | Path, name: str = "", overwrite: bool = True) -> None:
    """Refuse, in one line naming option ``name`` (if any) and ``path``, an output path that
    cannot be written: an existing directory, a folder that does not exist or is not
    writable, an existing file without ``overwrite``.  What every command checks before its
    work."""
    path = Path(path)
    where = f"{name} {path}" if name else str(path)
    if path.is_dir():
        raise SplatglError(f"{where}: is a directory; give a file name")
    parent = Path(os.path.abspath(path)).parent
    if not parent.is_dir():
        raise SplatglError(f"{where}: folder {path.parent} does not exist")
    if not os.access(parent, os.W_OK | os.X_OK):
        raise SplatglError(f"{where}: folder {path.parent} is not writable")
    if path.exists() and not overwrite:
        raise SplatglError(f"{where}: exists (use --force to replace it)")


class OutputFiles:
    """Named output paths, checked at construction and committed together.

    Args:
        targets: option name (used in messages, and as the key of :meth:`temp`) -> path; a
            ``None`` path (an option not given) is skipped.
        overwrite: whether an existing file may be replaced (directories never are).

    Raises:
        SplatglError: one line naming the option and path: the same file named twice, a path
            that is an existing directory, a folder that does not exist, an existing file
            without ``overwrite``.
    """

    def __init__(self, targets: dict[str, Path | str | None], overwrite: bool = True):
        self.targets = {name: Path(p) for name, p in targets.items() if p is not None}
        self._files: dict[str, AtomicTarget] = {}
        seen: dict[Path, str] = {}
        for name, path in self.targets.items():
            key = Path(os.path.abspath(path))
            if key in seen:
                raise SplatglError(f"{name} {path}: the same file as {seen[key]}; give each "
                                   "output its own name")
            seen[key] = name
            check_output_path(path, name, overwrite)

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
        (:func:`~splatgl.output.atomic.naming_targets`); a full disk's ``OSError`` without a file
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
