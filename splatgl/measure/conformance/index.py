"""A kit's ``index.json`` read and checked (:mod:`splatgl.measure.conformance.export` writes it).

A kit may come from anyone, so nothing in it is trusted: the index must be a JSON object whose
``cases`` is a list of objects, each with every field ``score`` and ``render`` use, of the right
type.  A case's ``name`` becomes a file name (``render`` writes ``OUT/NAME.exr``, ``score``
reads ``THEIRS/NAME.png``), so it must be a plain name: letters, digits, ``.``, ``_``, ``+``
and ``-``, starting with a letter or a digit (no folder separators, no ``..``, not absolute);
two cases may not share one.  The files a case names (``scene``, ``camera``,
``reference_exr``) must be relative paths inside the kit.  Anything else is refused in one line
naming index.json, the case and the value.
"""

from __future__ import annotations

import json
import math
import re
from pathlib import Path, PurePosixPath, PureWindowsPath

from ...errors import SplatglError
from ...scene.json_text import DuplicateKeyError, unique_keys

#: A plain case name (module doc).
PLAIN_NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9._+-]{0,127}")
PLAIN_NAME_RULE = "letters, digits, '.', '_', '+' and '-', starting with a letter or a digit"
#: The fields of a case that name a file of the kit.
FILE_FIELDS = ("scene", "camera", "reference_exr")
GENERATOR = "splatgl conformance export"


def _kind(value: object) -> str:
    """``value``'s JSON type with its article, for messages ("an object", "a list")."""
    if isinstance(value, bool):
        return "a boolean"
    if isinstance(value, (int, float)):
        return "a number"
    return {dict: "an object", list: "a list", str: "a string", type(None): "null"}.get(type(value), "a value")


def _is_number(value: object) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)


def _inside_kit(value: object) -> bool:
    """Whether ``value`` is a relative path with no ``..`` (in POSIX or Windows spelling)."""
    if not isinstance(value, str) or not value or "\0" in value:
        return False
    for pure in (PurePosixPath(value), PureWindowsPath(value)):
        if pure.is_absolute() or pure.anchor or ".." in pure.parts:
            return False
    return True


def _case_problem(entry: dict) -> str | None:
    """What is wrong with one case object (a clause naming the field and its value), or None."""
    name = entry.get("name")
    if not isinstance(name, str) or not PLAIN_NAME.fullmatch(name):
        shown = "missing" if "name" not in entry else repr(name)
        return f"field 'name' {shown}: not a plain name ({PLAIN_NAME_RULE})"
    for field in FILE_FIELDS:
        if not _inside_kit(entry.get(field)):
            shown = "missing" if field not in entry else repr(entry[field])
            return f"field '{field}' {shown}: not a relative path inside the kit"
    for field in ("width", "height"):
        v = entry.get(field)
        if not isinstance(v, int) or isinstance(v, bool) or v < 1:
            return f"field '{field}' {'missing' if field not in entry else repr(v)}: not a whole number >= 1"
    if not _is_number(entry.get("near")):
        return f"field 'near' {entry.get('near', 'missing')!r}: not a finite number"
    bg = entry.get("background")
    if not isinstance(bg, list) or len(bg) != 3 or not all(_is_number(v) for v in bg):
        return f"field 'background' {bg!r}: not a list of 3 finite numbers"
    tol = entry.get("tolerance")
    if not isinstance(tol, dict) or not all(_is_number(tol.get(k)) for k in ("min_psnr", "max_off_4")):
        return f"field 'tolerance' {tol!r}: not an object with numbers 'min_psnr' and 'max_off_4'"
    return None


def check_index(index: object, path: Path) -> dict:
    """``index`` (parsed from ``path``) when it is a valid kit index (module doc)."""
    if not isinstance(index, dict):
        raise SplatglError(f"{path}: not a conformance index (the JSON is {_kind(index)}, not an object)")
    if "cases" not in index:
        raise SplatglError(f"{path}: not a conformance index (field 'cases' missing)")
    cases = index["cases"]
    if not isinstance(cases, list):
        raise SplatglError(f"{path}: not a conformance index (field 'cases' is {_kind(cases)}, "
                           "not a list)")
    seen = set()
    for k, entry in enumerate(cases):
        if not isinstance(entry, dict):
            raise SplatglError(f"{path}: case {k} is {_kind(entry)}, not an object")
        problem = _case_problem(entry)
        name = entry.get("name")
        label = f"case {k} ({name})" if isinstance(name, str) and PLAIN_NAME.fullmatch(name) else f"case {k}"
        if problem:
            raise SplatglError(f"{path}: {label}: {problem}")
        if entry["name"] in seen:
            raise SplatglError(f"{path}: {label}: field 'name' {entry['name']!r}: named twice "
                               "(each case's image is named after it)")
        seen.add(entry["name"])
    return index


def load_index(kit: str | Path) -> dict:
    """The index of the kit in folder ``kit``, checked (module doc)."""
    kit = Path(kit)
    path = kit / "index.json"
    if not path.is_file():
        raise SplatglError(f"{kit}: not a conformance kit (no index.json; splatgl conformance "
                           "export writes one)")
    try:
        index = json.loads(path.read_bytes(), object_pairs_hook=unique_keys)
    except DuplicateKeyError as exc:
        raise SplatglError(f"{path}: {exc}") from None
    except (ValueError, UnicodeDecodeError) as exc:
        where = f" at line {exc.lineno} column {exc.colno}" if hasattr(exc, "lineno") else ""
        raise SplatglError(f"{path}: not valid JSON ({getattr(exc, 'msg', exc)}{where})") from None
    except OSError as exc:
        raise SplatglError(f"{path}: cannot read ({exc.strerror})") from None
    return check_index(index, path)


def kit_files(kit: str | Path, index: dict) -> list[Path]:
    """Every file of the kit that ``render`` and ``score`` read (index.json and each case's)."""
    kit = Path(kit)
    return [kit / "index.json"] + [kit / e[f] for e in index["cases"] for f in FILE_FIELDS]
