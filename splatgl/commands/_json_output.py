"""One ``--json`` convention for every command that reports figures.

``--json FILE`` writes the report as JSON to FILE (atomically; the usual text still prints,
then ``wrote FILE``); ``--json -``, or ``--json`` with no FILE, prints the JSON alone on
standard output.  A FILE must end in ``.json``: that is how a bare ``--json`` followed by a
scene (``splatgl info --json scene.ply``, the older spelling) stays a flag.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from ..writing.atomic import atomic_write_text
from ..errors import SplatglError
from ..writing.outputs import Inputs, same_file
from ._outputs import output_files

#: The FILE that means standard output.
STDOUT = "-"
OPTION = "--json"
SUFFIX = ".json"


def add_json_argument(p: argparse.ArgumentParser, what: str) -> None:
    """``--json [FILE]`` for ``what`` (e.g. "the statistics")."""
    p.add_argument(OPTION, nargs="?", const=STDOUT, default=None, metavar="FILE",
                   help=f"write {what} as JSON to FILE (*{SUFFIX}), or print only the JSON on "
                        f"standard output with - or no FILE")


def _left_as_argument(word: str, nxt: str) -> bool:
    """Whether ``nxt``, after ``word``, is a word a bare ``--json`` does not take as its FILE
    (not ``-``, not an option, not a name ending in .json)."""
    return (word == OPTION and nxt != STDOUT and not nxt.startswith("-")
            and not nxt.lower().endswith(SUFFIX))


def bare_json_first(parser: argparse.ArgumentParser, args: list[str]) -> list[str]:
    """``args`` with a bare ``--json`` made ``--json=-`` where the next word is not a JSON
    file name (so it stays a positional argument, as before ``--json`` took a FILE)."""
    if OPTION not in getattr(parser, "_option_string_actions", {}):
        return args
    out = list(args)
    for i, word in enumerate(out[:-1]):
        if word == "--":
            break
        if _left_as_argument(word, out[i + 1]):
            out[i] = f"{OPTION}={STDOUT}"
    return out


def json_file_hint(args: list[str]) -> str:
    """For an 'unrecognized arguments' line: why the word after a bare ``--json`` was not its
    FILE (``info x.ply --json i.txt`` left i.txt over), or "" where no word was left so."""
    for word, nxt in zip(args, args[1:]):
        if word == "--":
            break
        if _left_as_argument(word, nxt):
            return (f"; {OPTION} takes a FILE ending in {SUFFIX} (or - for standard output), so "
                    f"{nxt} was not taken as its FILE")
    return ""


def json_to_stdout(args: argparse.Namespace) -> bool:
    """Whether the JSON goes to standard output (then nothing else may be printed there)."""
    return getattr(args, "json", None) == STDOUT


def check_json_target(args: argparse.Namespace, files: dict[str, Path | None] | None = None,
                      inputs: Inputs | None = None) -> None:
    """Refuse a --json FILE that cannot be written or would overwrite a scene, before work:
    ``files`` (option name -> path) are the command's other outputs, which it must not be;
    no file the command reads may be it either (:func:`~._outputs.input_files` of ``args``
    plus ``inputs``), and an existing FILE is replaced only with ``--force``."""
    value = getattr(args, "json", None)
    if value is None or value == STDOUT:
        return
    path = Path(value)
    if not path.name.lower().endswith(SUFFIX) or path.name.lower() == SUFFIX:
        raise SplatglError(f"{OPTION} {value}: name the report *{SUFFIX} (or - for standard output)")
    if path.is_file():
        from ..formats import SNIFF_BYTES, sog
        with open(path, "rb") as fh:
            if sog.sniff(fh.read(SNIFF_BYTES)):
                raise SplatglError(f"{OPTION} {value}: is a scene (SOG meta.json), not a report; "
                                   "put the scene before --json")
    for name, other in (files or {}).items():
        if other is not None and same_file(other, path):
            raise SplatglError(f"{OPTION} {value}: the same file as {name}; give the report its "
                               "own name")
    output_files(args, {OPTION: path}, inputs)


def emit_json(args: argparse.Namespace, obj: object, indent: int | None = None) -> None:
    """The report ``obj`` (or its JSON text) to where --json says: printed, or written and
    announced."""
    text = obj.rstrip("\n") if isinstance(obj, str) else json.dumps(obj, indent=indent)
    if json_to_stdout(args):
        print(text)
        return
    atomic_write_text(args.json, text + "\n")
    print(f"wrote {args.json}")
