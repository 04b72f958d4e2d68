"""How scene loaders put file content into their one-line errors.

A damaged file can hold anything where a header word is expected: ANSI escape sequences, NUL
runs, megabytes without a newline.  Error lines quote such content only through :func:`quote`
(control characters escaped, length capped), and every reader runs under :func:`reader_guard`,
which escapes whatever is left in the final message, caps its length and keeps NumPy's
floating-point warnings (``invalid value encountered in cast`` ...) from printing on their own:
bad values are reported by the checks that name file and field
(:func:`splatgl.scene.splats.activate`), never by a stray warning line.
"""

from __future__ import annotations

import functools

import numpy as np

from ..errors import SceneFormatError

#: Most characters of file content one error message quotes (before escaping).
QUOTE_LIMIT = 60
#: Most characters of a whole loader error message (a last guard; quotes are capped first).
MESSAGE_LIMIT = 400


def _escape_char(ch: str) -> str:
    if ch.isprintable() or ch == " ":
        return ch
    code = ord(ch)
    if code <= 0xFF:
        return f"\\x{code:02x}"
    return f"\\u{code:04x}" if code <= 0xFFFF else f"\\U{code:08x}"


def escape(text: str) -> str:
    """``text`` with every non-printable character (control, NUL, ESC, line breaks, format
    characters such as bidi overrides) written as a ``\\xNN`` / ``\\uNNNN`` escape."""
    if text.isprintable():
        return text
    return "".join(_escape_char(ch) for ch in text)


def quote(value: bytes | str, limit: int = QUOTE_LIMIT) -> str:
    """File content for an error message: single-quoted, escaped, at most ``limit`` characters.

    Bytes keep printable ASCII and show every other byte as ``\\xNN``; text escapes
    non-printable characters (:func:`escape`).  Longer content is cut and says how long it
    was: ``'abc...' (5000 bytes)``.
    """
    if isinstance(value, (bytes, bytearray)):
        shown = "".join(chr(b) if 0x20 <= b <= 0x7E else f"\\x{b:02x}" for b in value[:limit])
        unit = "bytes"
    else:
        shown, unit = escape(str(value)[:limit]), "characters"
    if len(value) > limit:
        return f"'{shown}...' ({len(value)} {unit})"
    return f"'{shown}'"


def clean_message(message: str, limit: int = MESSAGE_LIMIT) -> str:
    """One safe line: control characters escaped, at most ``limit`` characters (then '...')."""
    message = escape(message)
    return message if len(message) <= limit else message[:limit - 3] + "..."


def reader_guard(read):
    """Decorate a format's ``read``: NumPy float warnings silenced, error message cleaned.

    Inside, ``np.errstate(all="ignore")``: overflow or NaN from damaged values flows into the
    arrays, where :func:`splatgl.scene.splats.activate` reports it by field and row.  A
    :class:`SceneFormatError` leaving ``read`` has its message passed through
    :func:`clean_message` (its ``path`` and ``field`` attributes are kept).
    """

    @functools.wraps(read)
    def guarded(*args, **kwargs):
        try:
            with np.errstate(all="ignore"):
                return read(*args, **kwargs)
        except SceneFormatError as exc:
            text = str(exc)
            safe = clean_message(text)
            if safe != text:
                exc.args = (safe,)
            raise

    return guarded
