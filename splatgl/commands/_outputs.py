"""The two rules every command's outputs follow, checked before any work, on every command alike
(one mechanism: :class:`splatgl.writing.outputs.OutputFiles` and
:func:`~splatgl.writing.outputs.check_output_path`):

* an output that is one of the files the command reads (the same path, or the same file
  through a symbolic or hard link) is refused in one line naming both options, ``--force`` or
  not (``compare --camera cam.json --json cam.json``);
* an output that exists is replaced only with ``--force`` (:func:`add_force_argument`).

:func:`input_files` knows the files a command reads from its parsed arguments (the scene, the
camera and transform files, ``--under``, ``--image``, a path file, ``IN``...); a command adds
what only it reads (a dataset's photographs) with ``extra``.
"""

from __future__ import annotations

import argparse
import os
from pathlib import Path
from typing import Iterable

from ..errors import SplatglError
from ..writing.outputs import (Inputs, InputIndex, OutputFiles, check_not_an_input, check_output_path,
                               folder_writable)

#: The one help text of ``--force``.
FORCE_HELP = ("replace output files that exist (an output that is one of the command's own "
              "input files is refused either way)")

#: Argument attribute -> the option named in messages, for every file a command may read.
READ_OPTIONS = (("scene", "SCENE"), ("scenes", "SCENE"), ("input", "IN"), ("inputs", "IN"),
                ("camera", "--camera"), ("under", "--under"), ("image", "--image"),
                ("transform", "--transform"), ("path", "--path"), ("cameras", "--cameras"))


def add_force_argument(p: argparse.ArgumentParser, help: str = FORCE_HELP) -> None:
    """``--force`` (``args.force``): replace existing outputs; ``help`` where it replaces more
    than files."""
    p.add_argument("--force", action="store_true", help=help)


def _file_values(value) -> list[Path]:
    """The paths among an argument's value(s): inline JSON (``--transform '{...}'``) and
    path specifications that name no file (``--path orbit:120``) are left out."""
    values = value if isinstance(value, (list, tuple)) else [value]
    paths = []
    for v in values:
        if v is None or not isinstance(v, (str, Path)):
            continue
        text = str(v)
        if text.lstrip().startswith("{") or text in ("", "-"):
            continue
        path = Path(text)
        if isinstance(v, Path) or path.is_file():
            paths.append(path)
    return paths


def input_files(args: argparse.Namespace, extra: Inputs | None = None) -> dict:
    """The files ``args``' command reads: option name -> path(s), plus ``extra`` (e.g. a
    dataset's photographs, ``{"--dataset": [...]}``)."""
    found: dict = {}
    for attr, option in READ_OPTIONS:
        paths = _file_values(getattr(args, attr, None))
        if paths:
            found[option] = paths
    found.update({k: v for k, v in (extra or {}).items() if v is not None})
    return found


def force(args: argparse.Namespace) -> bool:
    """Whether the command may replace existing outputs (``--force``)."""
    return bool(getattr(args, "force", False))


def output_files(args: argparse.Namespace, targets: dict, extra: Inputs | None = None) -> OutputFiles:
    """:class:`OutputFiles` of ``targets`` (option name -> path or None) checked against every
    file ``args``' command reads and against ``--force``."""
    return OutputFiles(targets, force(args), input_files(args, extra))


def check_output(args: argparse.Namespace, path: str | Path | None, option: str,
                 extra: Inputs | None = None) -> None:
    """:func:`check_output_path` of one output (``option`` ``path``; None: not given) against
    the command's inputs and ``--force``."""
    if path is not None:
        check_output_path(path, option, force(args), input_files(args, extra))


def check_outputs(args: argparse.Namespace, paths: Iterable[Path], option: str,
                  extra: Inputs | None = None, keep: bool = False) -> None:
    """Each of several files one option writes into a folder it makes and checks itself (a
    path's frames, eval's renders): none is a file the command reads, and none exists without
    ``--force``; ``keep``: existing files are allowed (``--resume`` keeps or completes them: no
    overwrite), though never an input, nor (``--force`` or not) a directory."""
    inputs = InputIndex(input_files(args, extra))   # many outputs against many inputs
    replace = force(args) or keep
    for path in paths:
        check_not_an_input(path, option, inputs)
        if path.is_dir():
            raise SplatglError(f"{option} {path}: is a directory; give a file name")
        if not replace and (path.exists() or path.is_symlink()):
            raise SplatglError(f"{option} {path}: exists (use --force to replace it)")


def check_out_folder(args: argparse.Namespace, names: Iterable[str], option: str = "--out") -> None:
    """``--out DIR`` (``args.out``), a folder for the files ``names`` (``bench.csv``, ...),
    checked before any measuring: not a file, its parent folder there and writable, and each
    file neither one the command reads nor (without ``--force``) one that exists."""
    folder = getattr(args, "out", None)
    if folder is None:
        return
    names = tuple(names)
    if folder.exists() and not folder.is_dir():
        listed = ", ".join(names[:-1]) + " and " + names[-1] if len(names) > 1 else names[0]
        raise SplatglError(f"{option} {folder}: is a file; {option} names a folder for {listed}")
    if folder.is_dir():
        output_files(args, {f"{option} ({name})": folder / name for name in names})
        return
    parent = Path(os.path.abspath(folder)).parent
    if not parent.is_dir():
        raise SplatglError(f"{option} {folder}: folder {folder.parent} does not exist")
    if not folder_writable(parent):
        raise SplatglError(f"{option} {folder}: folder {folder.parent} is not writable")
