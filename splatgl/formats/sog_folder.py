"""Publishing a SOG folder (``meta.json`` and the WebP textures it names) as a whole.

A reader opens ``meta.json`` and then the files it names, so ``meta.json`` is the switch: at
every instant it names a complete set of textures, the old scene's or the new one's, however
the write ends (a full disk, Ctrl-C, SIGTERM, a kill).

1. Every new texture is written to its hidden temporary beside the target
   (:func:`splatgl.writing.atomic.temp_path`) and checked to hold all its bytes.
2. When the old ``meta.json`` names none of the new textures' names, they are renamed into
   place (no reader looks at them) and step 4 follows.
3. Otherwise the old scene still needs those names, so a ``meta.json`` naming the temporaries
   is published first (the switch to the new scene); the textures are then written under their
   own names, which nothing names any more.
4. The final ``meta.json`` (the standard names) is published (atomically, as every file), and
   the textures that only the old scene named (an SH palette the new scene lacks, step 3's
   temporaries) are removed, so nothing of the old scene lingers.

Any failure before the switch removes the temporaries and leaves the old scene as it was; one
after it leaves the new scene complete.  Errors name ``meta.json`` (the user's output).
"""

from __future__ import annotations

import json
import os
from pathlib import Path

from ..writing.atomic import atomic_write_bytes, cannot_write, size_problem, temp_path, write_error


def named_files(meta_path: Path) -> set[str]:
    """The plain ``.webp`` file names the ``meta.json`` at ``meta_path`` names (empty when there
    is none or it cannot be read): the files a reader of it opens."""
    try:
        meta = json.loads(Path(meta_path).read_bytes().decode("utf-8"))
    except (OSError, UnicodeDecodeError, ValueError, RecursionError):
        return set()
    if not isinstance(meta, dict):
        return set()
    return {name for value in meta.values() if isinstance(value, dict)
            for name in (value.get("files") if isinstance(value.get("files"), list) else [])
            if isinstance(name, str) and name.lower().endswith(".webp") and "/" not in name
            and "\\" not in name and not name.startswith("..")}


def _renamed(meta: dict, names: dict[str, str]) -> bytes:
    """``meta`` as JSON with every file name in ``names`` replaced by its value."""
    out = {key: ({**value, "files": [names.get(n, n) for n in value["files"]]}
                 if isinstance(value, dict) and "files" in value else value)
           for key, value in meta.items()}
    return json.dumps(out).encode("utf-8")


def _put(path: Path, blob: bytes, target: Path) -> None:
    """Write ``blob`` to ``path`` (a temporary) and check it holds every byte."""
    path.write_bytes(blob)
    problem = size_problem(path, len(blob))
    if problem is not None:
        raise cannot_write(target, f"{path.name}: {problem}")


def publish(target: str | Path, blobs: dict[str, bytes], meta: dict) -> None:
    """Replace the SOG folder scene at ``target`` (its ``meta.json``) by ``meta`` and the
    textures ``blobs`` (file name -> bytes, the names ``meta`` gives), as the module notes say."""
    target = Path(target)
    folder = target.parent
    old = named_files(target)
    temps = {name: temp_path(folder / name) for name in blobs}
    copies = {name: temp_path(folder / f"copy-{name}") for name in blobs}
    try:
        for name, blob in blobs.items():
            _put(temps[name], blob, target)
        staged = bool(old & set(blobs))
        if staged:  # the switch to the new scene, under its temporaries' names
            atomic_write_bytes(target, _renamed(meta, {n: t.name for n, t in temps.items()}))
        for name, blob in blobs.items():
            if staged:  # the old scene's names are free now
                _put(copies[name], blob, target)
                os.replace(copies[name], folder / name)
            else:
                os.replace(temps[name], folder / name)
        atomic_write_bytes(target, json.dumps(meta).encode("utf-8"))
        for name in old - set(blobs):  # what only the old scene named
            (folder / name).unlink(missing_ok=True)
    except OSError as exc:
        raise write_error(target, exc) from None
    finally:
        named = named_files(target)  # what a reader opens now is never removed
        for tmp in [*temps.values(), *copies.values()]:
            if tmp.name not in named:
                tmp.unlink(missing_ok=True)
