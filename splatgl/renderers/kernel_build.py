"""The CPU renderer's kernels compiled in a process of their own, for one-shot commands
(issue 40 item 4: "compile them in the background on first use").

``--renderer auto`` draws with the CPU renderer on software devices only once numba's on-disk
cache holds its kernels (:func:`splatgl.renderers.cpu.kernels_ready`); a compile takes about
half a minute.  The viewer compiles them on a thread while it runs
(:func:`splatgl.renderers.auto.compile_in_background`).  A ``render`` is over in a second or
two, far sooner than the compile, and must not switch renderers halfway through a path (its
frames would come from two renderers), so it draws with the quad path and :func:`start` runs
the compile in a detached, low-priority process that fills numba's cache and ends: the next
``render`` finds the kernels ready.

A stamp file in the user's cache folder (``$XDG_CACHE_HOME/splatgl`` or ``~/.cache/splatgl``),
one per splatgl and numba version and Python environment, says what that process is doing
(``compiling: <host> <pid>``, ``ready`` or ``failed: <the error's first line>``), so that it
is started once, not by every command, and what the commands say is true: while it is younger
than :data:`STALE_S` seconds no other process starts; an older one (kernels whose cache was
lost since), or a ``compiling`` one whose process is gone from this host (killed, a reboot),
lets the next command start again.  Nothing here runs where the
stamp folder cannot be written: the command then says how to compile them in the foreground
(``--renderer cpu``); nor where ``SPLATGL_RENDERER_AUTO=quad`` keeps ``auto`` on the quad path.

Run as ``python -m splatgl.renderers.kernel_build STAMP`` by :func:`start` only.
"""

from __future__ import annotations

import hashlib
import os
import socket
import subprocess
import sys
import sysconfig
import time
from dataclasses import dataclass
from importlib import metadata
from pathlib import Path

#: Seconds after which a stamp no longer holds a new compile back (one takes about 30 s on
#: 2 cores; a stamp this old belongs to a compile that died, or to kernels lost since).
STALE_S = 600
#: What the stamp says while the process compiles, and once it is done.
COMPILING, READY, FAILED = "compiling", "ready", "failed"
#: The child process's niceness increment: it must not slow the user's next command much.
NICE = 10


@dataclass(frozen=True)
class Build:
    """What the stamp says (``state``: COMPILING, READY or FAILED; ``why``: the error's first
    line where FAILED, the compiling process's host and pid where COMPILING) and how old it is
    in seconds; ``gone``: it says COMPILING but its process no longer runs on this host."""

    state: str
    age: float
    why: str = ""
    gone: bool = False

    @property
    def fresh(self) -> bool:
        return self.age < STALE_S and not self.gone


def _gone(why: str) -> bool:
    """Whether ``why`` (a COMPILING stamp's ``<host> <pid>``) names a process of this host that
    no longer runs; False where it names none, or another host's (which cannot be asked)."""
    host, _, pid = why.rpartition(" ")
    if not pid.isdigit() or host != socket.gethostname():
        return False
    try:
        os.kill(int(pid), 0)
    except ProcessLookupError:
        return True
    except OSError:   # it runs, as another user (EPERM)
        return False
    return False


def stamp_path() -> Path | None:
    """The stamp file of this splatgl and numba version; None where the cache folder is not
    an absolute path (no home folder)."""
    from .. import __version__

    try:
        numba_version = metadata.version("numba")
    except metadata.PackageNotFoundError:
        numba_version = "none"
    root = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    if not os.path.isabs(root):   # HOME unset ("~" left as it is), or a relative XDG path
        return None
    # one stamp an environment and checkout: each has its own numba cache (__pycache__ beside
    # the kernels' sources), so another's "ready" says nothing of this one's
    where = hashlib.sha1(f"{sys.prefix}\0{Path(__file__).resolve().parent}".encode()).hexdigest()
    return Path(root) / "splatgl" / f"cpu-kernels-{__version__}-numba-{numba_version}-{where[:10]}"


def read(stamp: Path | None = None) -> Build | None:
    """What the stamp says, or None where there is none (or it cannot be read)."""
    stamp = stamp or stamp_path()
    if stamp is None:
        return None
    try:
        text = stamp.read_text(encoding="utf-8").strip()
        age = max(0.0, time.time() - stamp.stat().st_mtime)
    except (OSError, UnicodeDecodeError):
        return None
    state, _, why = text.partition(":")
    if state not in (COMPILING, READY, FAILED):
        return None
    why = why.strip()
    return Build(state, age, why, state == COMPILING and _gone(why))


def _write(stamp: Path, text: str) -> None:
    """Write the stamp whole (a reader sees the old text or the new, never half)."""
    stamp.parent.mkdir(parents=True, exist_ok=True)
    part = stamp.with_name(f"{stamp.name}.{os.getpid()}.part")
    part.write_text(text + "\n", encoding="utf-8")
    os.replace(part, stamp)


def _spawn(argv: list[str], **kwargs) -> None:
    """Start ``argv`` and leave it running (its own session: Ctrl-C in the terminal and the
    command's exit leave it be)."""
    subprocess.Popen(argv, **kwargs)


def start() -> Build | None:
    """Start the compile in a detached process unless a fresh stamp says one ran or runs; the
    stamp as it stands afterwards (``age`` 0 where this call started it), or None where no
    process could be started (no writable cache folder, no ``fork``)."""
    stamp = stamp_path()
    build = read(stamp) if stamp is not None else None
    if build is not None and build.fresh:
        return build
    if stamp is None or not hasattr(os, "setsid"):
        return None
    try:
        _write(stamp, COMPILING)
    except OSError:
        return None
    env = dict(os.environ)
    here = str(Path(__file__).resolve().parents[2])   # where this splatgl is imported from
    if here not in {str(Path(p).resolve()) for p in sysconfig.get_paths().values()}:
        # a checkout on sys.path (not installed): the child, started elsewhere, must find it
        env["PYTHONPATH"] = os.pathsep.join(p for p in (here, env.get("PYTHONPATH")) if p)
    try:
        _spawn([sys.executable, "-m", "splatgl.renderers.kernel_build", str(stamp)],
               stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
               cwd=os.path.dirname(stamp), env=env, start_new_session=True, close_fds=True)
    except OSError:
        stamp.unlink(missing_ok=True)   # nothing compiles: let the next command try again
        return None
    return Build(COMPILING, 0.0)


def main(argv: list[str] | None = None) -> int:
    """The child: compile (or load) the kernels, then say so in the stamp."""
    args = sys.argv[1:] if argv is None else argv
    if len(args) != 1:
        print("usage: python -m splatgl.renderers.kernel_build STAMP (run by splatgl itself)",
              file=sys.stderr)
        return 2
    stamp = Path(args[0])
    _write(stamp, f"{COMPILING}: {socket.gethostname()} {os.getpid()}")   # who, should it die
    try:
        from .cpu import prepare

        prepare(lambda *_: None)
    except BaseException as exc:   # noqa: BLE001 (said in the stamp; the parent reads it)
        first = (str(exc).strip().splitlines() or [type(exc).__name__])[0]
        _write(stamp, f"{FAILED}: {first[:300]}")
        return 1
    _write(stamp, READY)
    return 0


if __name__ == "__main__":
    try:
        os.nice(NICE)
    except OSError:
        pass
    sys.exit(main())
