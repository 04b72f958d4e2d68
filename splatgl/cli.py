"""The ``splatgl`` command line: one sub-command per module in :mod:`splatgl.commands`.

Every sub-command module defines ``NAME``, ``HELP``, ``add_arguments(parser)`` and
``run(args) -> int``.  ``splatgl --version`` prints the version; ``splatgl`` alone prints the
commands (the top-level help) on stderr and exits with 2, as a usage error does.  Bad input
(any :class:`SplatglError`, and any bad argument) prints one line and exits with 2, never a
traceback.  Ctrl-C (SIGINT) and SIGTERM stop the command the
same way, at any moment including start-up: the exception unwinds, so every temporary file is
removed, and one line says so (exit 130 or 143).  A closed stdout (``splatgl info S | head -1``)
ends the command quietly (exit 141, as a shell reports SIGPIPE).

Only the standard library is imported at module level: the commands (NumPy, moderngl, ...)
load inside :func:`main`, where an interrupt is already handled.
"""

from __future__ import annotations

import sys


def _quiet_interrupt_hook(exc_type, exc, tb, _default=sys.excepthook):
    """Ctrl-C before :func:`main` could handle it (while Python imports this module): one line."""
    if issubclass(exc_type, KeyboardInterrupt):
        print("splatgl: interrupted", file=sys.stderr)
    else:
        _default(exc_type, exc, tb)


if sys.excepthook is sys.__excepthook__:  # an interactive shell keeps its own hook
    sys.excepthook = _quiet_interrupt_hook

import os  # noqa: E402  (after the hook: these imports are the start-up it covers)
import signal  # noqa: E402

EXIT_BAD_INPUT = 2
EXIT_INTERRUPTED = 128 + signal.SIGINT
EXIT_TERMINATED = 128 + signal.SIGTERM
EXIT_BROKEN_PIPE = 128 + signal.SIGPIPE


class Terminated(KeyboardInterrupt):
    """Raised in the main thread by SIGTERM, so it unwinds (and cleans up) exactly like Ctrl-C."""


#: Signals received during this :func:`main` call (an interrupt inside a C extension's import
#: can surface as an ImportError: the flag tells it was the user's doing).
_received: list[int] = []


def _on_signal(signum, frame) -> None:
    _received.append(signum)
    raise Terminated() if signum == signal.SIGTERM else KeyboardInterrupt()


class BadArguments(Exception):
    """An argument error; :func:`main` prints it as one line and returns 2."""


def _parser_class():
    import argparse

    class OneLineParser(argparse.ArgumentParser):
        """Argument errors as one line with the --help hint, under the one prefix every error
        has (``splatgl: error: ...``, as :func:`main` prints a SplatglError)."""

        def error(self, message: str):
            raise BadArguments(f"splatgl: error: {message} (see {self.prog} --help)")

        def parse_known_args(self, args=None, namespace=None):
            if args is not None:   # a sub-command's words: the older bare --json spelling
                from .commands._json_output import bare_json_first
                args = bare_json_first(self, negative_values_joined(self, args))
            return super().parse_known_args(args, namespace)

    return OneLineParser


def negative_values_joined(parser, args: list[str]) -> list[str]:
    """``args`` with ``--memory -1G`` written ``--memory=-1G``: a value after an option that
    takes one, starting with '-' and a digit or '.', or one of the option's choices (``--up
    -y``), is that option's value, so the option's own check refuses it by name.  argparse takes only plain numbers (-1, -2.5) so; -1G or
    -1e3 it took for an unknown option and said 'expected one argument'."""
    actions = getattr(parser, "_option_string_actions", {})
    out: list[str] = []
    words = iter(args)
    for word in words:
        if word == "--":
            out += [word, *words]
            break
        action = actions.get(word)
        if action is not None and action.nargs is None:
            value = next(words, None)
            if value is None:
                out.append(word)
            elif len(value) > 1 and value[0] == "-" and (value[1].isdigit() or value[1] == "."
                                                         or value in (action.choices or ())):
                out.append(f"{word}={value}")   # (--up -y: one of its choices)
            else:
                out += [word, value]
        else:
            out.append(word)
    return out


def _command_modules():
    import importlib
    import pkgutil

    from . import commands

    mods = []
    for info in sorted(pkgutil.iter_modules(commands.__path__), key=lambda i: i.name):
        if not info.name.startswith("_"):
            mods.append(importlib.import_module(f"{commands.__name__}.{info.name}"))
    return sorted(mods, key=lambda m: getattr(m, "ORDER", 50))


def build_parser():
    """The ``splatgl`` argument parser (an :class:`argparse.ArgumentParser`)."""
    import argparse

    from . import __version__

    parser = _parser_class()(
        prog="splatgl",
        description="Render trained Gaussian-splat scenes (3DGS, 2DGS) through OpenGL.",
        epilog="'splatgl COMMAND --help' explains a command and its options.",
    )
    parser.add_argument("--version", action="version", version=f"splatgl {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for mod in _command_modules():
        p = sub.add_parser(mod.NAME, help=mod.HELP, description=getattr(mod, "DESCRIPTION", mod.HELP),
                           formatter_class=argparse.RawDescriptionHelpFormatter)
        mod.add_arguments(p)
        p.set_defaults(_run=mod.run, _parser=p)
    return parser


#: ``SPLATGL_DEBUG_WARNINGS=1`` shows NumPy's numeric warnings as Python prints them (file, line
#: and source), each one, instead of :func:`_warning_text`'s single splatgl line.
DEBUG_WARNINGS_ENV = "SPLATGL_DEBUG_WARNINGS"
#: Whether this run already printed its line about numeric warnings (:func:`main` resets it).
_numeric_reported: list[bool] = []


def _where(filename: str, lineno: int) -> str:
    """``splatgl/cameras/view.py:76`` (the path from the package's folder on), else the file name."""
    parts = filename.replace("\\", "/").split("/")
    if "splatgl" in parts:
        parts = parts[len(parts) - 1 - parts[::-1].index("splatgl"):]
    else:
        parts = parts[-1:]
    return f"{'/'.join(parts)}:{lineno}"


def _warning_text(message, category, filename: str, lineno: int) -> str | None:
    """The one ``splatgl: warning:`` line of a warning (None: say nothing more this run).

    splatgl's own warnings are already sentences.  A NumPy floating-point warning ("overflow
    encountered in cast") is a bug's symptom or an input splatgl failed to refuse: it is said
    once a run, where it happened, never as NumPy's raw text alone.  GLFW's errors arrive from
    pyGLFW as ``(65550) b'X11: ...'``: the bytes are decoded.
    """
    text = str(message)
    if category.__name__ == "GLFWError":
        import ast
        import re

        match = re.fullmatch(r"\((\d+)\) (b'.*'|b\".*\")", text, re.S)
        if match:
            try:
                text = ast.literal_eval(match.group(2)).decode("utf-8", "replace")
            except (ValueError, SyntaxError):
                pass
        return f"window system: {' '.join(text.split())}"
    numeric = issubclass(category, RuntimeWarning) and (
        "encountered in" in text or "/numpy/" in filename.replace("\\", "/"))
    if not numeric:
        return text
    if _numeric_reported:
        return None
    _numeric_reported.append(True)
    return (f"a computation went out of range at {_where(filename, lineno)} (NumPy: {text}); "
            "the output may hold inf or NaN values. Please report it with the command "
            f"({DEBUG_WARNINGS_ENV}=1 shows every such warning)")


def _one_line_warning(message, category, filename, lineno, file=None, line=None):
    out = sys.stderr if file is None else file
    if (os.environ.get(DEBUG_WARNINGS_ENV, "") not in ("", "0")
            and issubclass(category, RuntimeWarning)):
        import warnings

        out.write(warnings.formatwarning(message, category, filename, lineno, line))
        return
    text = _warning_text(message, category, filename, lineno)
    if text is not None:
        print(f"splatgl: warning: {text}", file=out)


def _silence_stdout() -> None:
    """Point stdout at /dev/null so the interpreter's final flush cannot raise again."""
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
    except (OSError, ValueError, AttributeError):
        pass


def main(argv: list[str] | None = None) -> int:
    handled = (signal.SIGINT, signal.SIGTERM)
    previous = {}
    del _received[:]
    del _numeric_reported[:]
    try:
        # Handlers can only be installed from the main thread (tests may call main() from
        # others); there Ctrl-C still raises KeyboardInterrupt, SIGTERM keeps its default.
        for sig in handled:
            if signal.getsignal(sig) is not signal.SIG_IGN:  # nohup'd: stay ignored
                previous[sig] = signal.signal(sig, _on_signal)
    except ValueError:
        pass
    try:
        import warnings

        from .errors import SplatglError, note_of

        parser = build_parser()
        if not (sys.argv[1:] if argv is None else argv):   # bare 'splatgl': the commands, and
            print(parser.format_help(), end="", file=sys.stderr)   # 2 so that scripts notice
            return EXIT_BAD_INPUT
        try:
            args, unknown = parser.parse_known_args(argv)
            if unknown:   # named by the sub-command, whose --help lists what it takes
                from .commands._json_output import json_file_hint

                hint = json_file_hint([str(a) for a in (sys.argv[1:] if argv is None else argv)])
                getattr(args, "_parser", parser).error(
                    f"unrecognized arguments: {' '.join(unknown)}{hint}")
        except BadArguments as exc:
            print(exc, file=sys.stderr)
            return EXIT_BAD_INPUT
        warnings.showwarning = _one_line_warning
        try:
            code = int(args._run(args) or 0)
        except SplatglError as exc:
            note = note_of(exc)
            print(f"splatgl: error: {exc}{'' if note is None else '; ' + note}", file=sys.stderr)
            code = EXIT_BAD_INPUT
        sys.stdout.flush()  # a closed pipe shows here, not at the interpreter's exit
        return code
    except BrokenPipeError:
        _silence_stdout()
        return EXIT_BROKEN_PIPE
    except BaseException as exc:
        if not (_received or isinstance(exc, KeyboardInterrupt)) or isinstance(exc, SystemExit):
            raise
        # Ctrl-C or SIGTERM, possibly surfacing as another error (an import interrupted
        # inside a C extension); the unwinding has removed every temporary file.
        terminated = isinstance(exc, Terminated) or signal.SIGTERM in _received
        from .errors import note_of   # (the import above may not have run yet)

        note = note_of(exc)   # what the command left (kept frames, how to resume)
        print(("splatgl: terminated" if terminated else "splatgl: interrupted")
              + ("" if note is None else f": {note}"), file=sys.stderr)
        return EXIT_TERMINATED if terminated else EXIT_INTERRUPTED
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler if handler is not None else signal.SIG_DFL)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
