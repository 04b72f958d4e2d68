"""Where ``conformance export DIR`` may write, and how it replaces an older kit.

``DIR`` must not exist, or (with ``--force``) be a file or a folder that is recognisably a kit
``export`` wrote: an ``index.json`` it generated, ``README.md`` and ``cases/`` and nothing else,
each case folder named in the index and holding only the kit's own files.  Any other folder (a
project with its sources, the current folder, one that holds it) is refused even with
``--force``: it would be deleted.  These checks run before any work.

The new kit is written under a temporary name beside ``DIR``; when it is complete the old one
(re-checked: still a kit) is renamed aside, the new one renamed into place and the old one
removed, with Ctrl-C and SIGTERM held back for those few renames, so that an interrupted or
failed export leaves the old kit (or file) as it was and nothing else behind.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import signal
from pathlib import Path

from ...errors import SplatglError
from ...writing.outputs import folder_writable
from .index import GENERATOR, load_index

#: What a kit's folder holds, and each case folder.
KIT_ENTRIES = frozenset({"index.json", "README.md", "cases"})
CASE_FILES = frozenset({"scene.ply", "camera.json", "reference.exr", "reference.png"})


def kit_problem(folder: str | Path) -> str | None:
    """Why ``folder`` is not a kit ``export`` wrote (a clause), or None when it is one."""
    folder = Path(folder)
    try:
        names = sorted(os.listdir(folder))
        extra = [n for n in names if n not in KIT_ENTRIES]
        if extra:
            more = f" and {len(extra) - 1} more" if len(extra) > 1 else ""
            return f"it holds {extra[0]!r}{more}, which no kit holds"
        if "index.json" not in names:
            return "it has no index.json" if names else "it is an empty folder, not a kit"
        try:
            index = load_index(folder)
        except SplatglError as exc:
            return f"its index.json is not a kit's ({str(exc).split(': ', 1)[-1]})"
        if index.get("generator") != GENERATOR:
            return f"its index.json was not written by {GENERATOR}"
        cases = folder / "cases"
        if not cases.exists():
            return None
        if cases.is_symlink() or not cases.is_dir():
            return "its cases/ is not a folder"
        known = {e["name"] for e in index["cases"]}
        for case in sorted(os.listdir(cases)):
            path = cases / case
            if case not in known or path.is_symlink() or not path.is_dir():
                return f"cases/{case} is no case of its index.json"
            extra = sorted(set(os.listdir(path)) - CASE_FILES)
            if extra:
                return f"cases/{case} holds {extra[0]!r}, which no kit holds"
    except OSError as exc:
        return f"it cannot be read ({exc.strerror})"
    return None


def _holds_cwd(path: Path) -> bool:
    here = os.path.realpath(os.getcwd())
    there = os.path.realpath(path)
    return here == there or here.startswith(there.rstrip(os.sep) + os.sep)


def check_export_target(out: str | Path, force: bool = False) -> None:
    """Refuse, in one line naming ``out``, a kit folder ``export`` may not write (module doc)."""
    out = Path(out)
    if not Path(os.path.abspath(out)).name or _holds_cwd(out):
        raise SplatglError(f"{out}: is the current folder or holds it; export the kit into a new "
                           "folder of its own (splatgl conformance export kit/)")
    if out.is_symlink():
        raise SplatglError(f"{out}: is a symbolic link; name the kit's folder itself")
    if out.exists():
        if not force:
            raise SplatglError(f"{out}: exists (use --force to replace it)")
        if out.is_dir():
            problem = kit_problem(out)
            if problem is not None:
                raise SplatglError(f"{out}: not a conformance kit ({problem}); --force replaces "
                                   "only a kit (or a file), never a folder holding anything else")
        elif not out.is_file():
            raise SplatglError(f"{out}: is neither a file nor a folder; give the kit another name")
    parent = Path(os.path.abspath(out)).parent
    if not parent.is_dir():
        raise SplatglError(f"{out}: folder {out.parent} does not exist")
    if not folder_writable(parent):
        raise SplatglError(f"{out}: folder {out.parent} is not writable")


@contextlib.contextmanager
def _signals_held():
    """Ctrl-C and SIGTERM delivered only after the block (where the platform can hold them)."""
    held = {signal.SIGINT, signal.SIGTERM}
    if not hasattr(signal, "pthread_sigmask"):
        yield
        return
    old = signal.pthread_sigmask(signal.SIG_BLOCK, held)
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, old)


def _remove(path: Path) -> None:
    if path.is_dir() and not path.is_symlink():
        shutil.rmtree(path, ignore_errors=True)
    else:
        path.unlink(missing_ok=True)


def replace_with(tmp: Path, out: Path, force: bool) -> None:
    """Rename the complete folder ``tmp`` onto ``out``, replacing an old kit or file there
    (re-checked first: the folder may have changed during the export); on any failure the old
    one stays."""
    if out.exists() or out.is_symlink():
        check_export_target(out, force)
    old = out.with_name(f".{out.name}.old{os.getpid()}")
    with _signals_held():
        had_old = out.exists()
        if had_old:
            os.rename(out, old)
        try:
            os.rename(tmp, out)
        except BaseException:
            if had_old:
                os.rename(old, out)
            raise
        if had_old:
            _remove(old)
