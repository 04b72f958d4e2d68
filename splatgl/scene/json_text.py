"""JSON as the command-line options and small files give it, read strictly: a key repeated in
one object is refused (Python's ``json`` silently keeps the last, so a typo'd duplicate would be
ignored without a word).

:func:`unique_keys` is the ``object_pairs_hook`` for any ``json.loads``/``json.load`` that
wants this rule; :func:`loads_strict` parses text with it and turns every failure into one
:class:`~splatgl.errors.SplatglError` line naming ``what`` (the option or file).
"""

from __future__ import annotations

import json

from ..errors import SplatglError


class DuplicateKeyError(ValueError):
    """A JSON object repeats ``key``."""

    def __init__(self, key: str):
        super().__init__(f"key {key!r} given twice in one object (JSON keeps only the last)")
        self.key = key


def unique_keys(pairs) -> dict:
    """``object_pairs_hook`` refusing a repeated key (:class:`DuplicateKeyError`)."""
    out: dict = {}
    for key, value in pairs:
        if key in out:
            raise DuplicateKeyError(key)
        out[key] = value
    return out


def loads_strict(text: str, what: str) -> object:
    """The parsed JSON ``text``; one SplatglError line naming ``what`` when it is not JSON or
    repeats a key in an object."""
    try:
        return json.loads(text, object_pairs_hook=unique_keys)
    except DuplicateKeyError as exc:
        raise SplatglError(f"{what}: {exc}") from None
    except json.JSONDecodeError as exc:
        raise SplatglError(f"{what}: not JSON ({exc.msg} at line {exc.lineno} column "
                           f"{exc.colno})") from None
    except RecursionError:
        raise SplatglError(f"{what}: not JSON (nested too deeply)") from None
