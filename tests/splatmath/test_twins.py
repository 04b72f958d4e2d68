"""Every shader names its NumPy twin, the twin exists, and some test uses it (DESIGN.md 5: each
GPU stage has a same-named pure-array twin).

The rule.  A shader's header is its leading ``//`` comment block (after an optional ``#version``
line).  It holds one or more twin entries, each a line ``// Twin: ...`` continued on the next
header lines while a line ends with ``,`` or ``;``:

    // Twin: splatgl/splatmath/project.py project(), ellipse_axes();
    //   splatgl/lod/selection.py blended_scene().

that is ``;``-separated groups of a module path under ``splatgl/`` and its ``name()`` list (a
``Class.method()`` names a method), with an optional final ``.``; or ``// Twin: none (reason)``
for plumbing that computes nothing a twin could check (a full-screen triangle, a benchmark's
cost floor, storage accessors, placing a corner from axes whose twin another piece names).
Every named module must import, every name must resolve to a callable, and every name (its last
part for a method) must appear as a word in some test file other than this one: a twin that no
test mentions is certainly not compared with its shader (a mention alone proves less).
"""

from __future__ import annotations

import importlib
import re
from pathlib import Path

import pytest

from splatgl.gl.shaders import shader_dir

REPO = Path(__file__).resolve().parents[2]
VIEWER_SHADERS = REPO / "splatgl" / "viewer" / "shaders"
_NAME = r"[A-Za-z_]\w*(?:\.[A-Za-z_]\w*)*\(\)"
_GROUP = re.compile(rf"(splatgl/[\w/]+\.py)\s+({_NAME}(?:\s*,\s*{_NAME})*)")
_NONE = re.compile(r"none \(.+\)")


def shader_files() -> list[Path]:
    root = shader_dir()
    found = sorted(p for p in root.rglob("*") if p.suffix in (".glsl", ".comp", ".vert", ".frag"))
    return found + sorted(VIEWER_SHADERS.glob("*.*"))


def header(text: str) -> list[str]:
    """The leading comment lines, without their ``//``."""
    lines = text.splitlines()
    if lines and lines[0].startswith("#version"):
        lines = lines[1:]
    out = []
    for line in lines:
        if not line.startswith("//"):
            break
        out.append(line[2:].strip())
    return out


def twin_entries(text: str) -> list[str]:
    """The twin entries of a shader's header, continuation lines joined."""
    entries: list[str] = []
    continuing = False
    for line in header(text):
        if line.startswith("Twin:"):
            entries.append(line[len("Twin:"):].strip())
        elif continuing:
            entries[-1] += " " + line
        else:
            continue
        continuing = entries[-1].endswith((",", ";"))
    return entries


def parse(entry: str) -> list[tuple[str, list[str]]]:
    """``[(module path, [names])]`` of one entry ([] for ``none (reason)``); ValueError if it
    breaks the grammar of the module doc."""
    body = entry[:-1] if entry.endswith(".") else entry
    if _NONE.fullmatch(body):
        return []
    groups = []
    for part in body.split(";"):
        m = _GROUP.fullmatch(part.strip())
        if m is None:
            raise ValueError(f"not 'path name(), ...' nor 'none (reason)': {part.strip()!r}")
        groups.append((m.group(1), [n.strip()[:-2] for n in m.group(2).split(",")]))
    return groups


def twins() -> dict[str, list[tuple[str, list[str]]]]:
    """Shader (relative to the repository) -> its parsed twin groups; AssertionError listing
    every shader whose header breaks the rule."""
    out, bad = {}, []
    for path in shader_files():
        rel = path.relative_to(REPO).as_posix() if REPO in path.parents else path.name
        entries = twin_entries(path.read_text())
        if not entries:
            bad.append(f"{rel}: no '// Twin:' line in the header")
            continue
        try:
            out[rel] = [g for e in entries for g in parse(e)]
        except ValueError as exc:
            bad.append(f"{rel}: {exc}")
    assert not bad, "\n".join(bad)
    return out


def test_every_shader_names_its_twin_or_says_why_not():
    found = twins()
    assert len(found) == len(shader_files()) > 30
    stages = [s for s, groups in found.items() if groups and not s.endswith(".glsl")]
    assert len(stages) >= 15, "most stages have a twin"


def test_named_twins_exist():
    missing = []
    for shader, groups in twins().items():
        for path, names in groups:
            module_name = path[:-3].replace("/", ".")
            if not (REPO / path).is_file():
                missing.append(f"{shader}: {path} does not exist")
                continue
            module = importlib.import_module(module_name)
            for name in names:
                obj = module
                for part in name.split("."):
                    obj = getattr(obj, part, None)
                if not callable(obj):
                    missing.append(f"{shader}: {path} has no function {name}")
    assert not missing, "\n".join(missing)


def test_named_twins_are_used_by_a_test():
    tests = "\n".join(p.read_text() for p in sorted(Path(__file__).parents[1].rglob("*.py"))
                      if p.name != Path(__file__).name)
    unused = sorted({f"{shader}: {name} ({path})"
                     for shader, groups in twins().items() for path, names in groups
                     for name in names
                     if not re.search(rf"\b{re.escape(name.split('.')[-1])}\b", tests)})
    assert not unused, "twins no test mentions:\n" + "\n".join(unused)


@pytest.mark.parametrize("text,why", [
    ("// A pass.\nvoid main() {}\n", "no twin line"),
    ("// Twin: splatgl/splatmath/project.py (same names).\n", "names must be listed"),
    ("// Twin: splatgl/splatmath/project.py project + ellipse_axes.\n", "names are name()"),
    ("// Twin: none.\n", "none needs a reason"),
])
def test_the_rule_refuses_vague_headers(text, why):
    entries = twin_entries(text)
    with pytest.raises((ValueError, AssertionError)):
        assert entries, why
        for entry in entries:
            parse(entry)


def test_the_rule_reads_continuations_and_stops_at_the_header():
    text = ("#version 430 core\n// Does things.\n// Twin: splatgl/a.py f(), g(),\n//   h();\n"
            "//   splatgl/b.py C.m().\n// More prose.\nvoid main() {}\n// Twin: none (late)\n")
    assert [g for e in twin_entries(text) for g in parse(e)] == [
        ("splatgl/a.py", ["f", "g", "h"]), ("splatgl/b.py", ["C.m"])]
