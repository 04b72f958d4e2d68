"""docs/ holds the design notes (.md) and the pictures they show; raw benchmark output (JSON,
JSONL, CSV, TXT, measurement plots, generated tables) lives in docs/results/.  Every relative
link of README.md and the notes points at a file that exists, and so does every source path
they name (``splatgl/order/cull.py``, ``shaders/cameras/<model>.glsl``) and every dotted name
(``splatgl.order.chunks.ChunkedCull``): a module that moves or goes fails here until the docs
follow it."""

from __future__ import annotations

import importlib
import re
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
DOCS = REPO / "docs"
_LINK = re.compile(r"\]\(([^)#\s]+)(?:#[^)]*)?\)")
#: A source path with at least one folder: ``splatgl/cameras/view.py``, ``lib/camera.glsl``,
#: ``shaders/tile_*.comp``, ``shaders/cameras/<model>.glsl``.  Not inside a longer path or a URL.
_SOURCE_PATH = re.compile(r"(?<![\w./:-])((?:[\w.<>{}*-]+/)+[\w<>{}*-]+\.(?:py|glsl|vert|frag|comp|sh))\b")
#: Folders a path in the docs may be relative to, besides the page's own: the repository, the
#: package (``order/cull.py``) and the shader folder (``lib/camera.glsl``).
_PATH_ROOTS = (REPO, REPO / "splatgl", REPO / "shaders")
#: A dotted name in the package: ``splatgl.order.chunks.ChunkedCull``, ``splatgl.Renderer``.
_DOTTED = re.compile(r"\bsplatgl(?:\.[A-Za-z_]\w*)+")


def _pages() -> list[Path]:
    return [REPO / "README.md", *sorted(DOCS.rglob("*.md"))]


def _path_exists(name: str, page: Path) -> bool:
    """Whether ``name`` names a file from one of :data:`_PATH_ROOTS` or the page's folder;
    a placeholder (``<model>``, ``{CAMERA_MODEL}``, ``*``) must match at least one file."""
    pattern = re.sub(r"<[^>]*>|\{[^}]*\}", "*", name)
    for root in (*_PATH_ROOTS, page.parent):
        if any(root.glob(pattern)) if "*" in pattern else (root / pattern).is_file():
            return True
    return False


def _dotted_problem(name: str) -> str | None:
    """Why ``name`` (``splatgl.a.b.attr...``) does not resolve, or None: the longest prefix that
    is a module file of the package is imported, and the rest looked up as attributes."""
    parts = name.split(".")
    k = len(parts)
    while k > 1 and not any((REPO.joinpath(*parts[:k]).with_suffix(".py").is_file(),
                             (REPO.joinpath(*parts[:k]) / "__init__.py").is_file())):
        k -= 1
    obj = importlib.import_module(".".join(parts[:k]))
    for i, attr in enumerate(parts[k:], start=k):
        if not hasattr(obj, attr):
            return f"{'.'.join(parts[:i])} has no {attr!r}"
        obj = getattr(obj, attr)
    return None


def test_raw_output_lives_in_results():
    loose = sorted(p.name for p in DOCS.iterdir()
                   if p.is_file() and p.suffix not in (".md", ".png"))
    assert not loose, f"raw output belongs in docs/results/: {loose}"
    assert any((DOCS / "results").glob("*.json")), "the measurements moved, not vanished"


def test_relative_links_resolve():
    pages = _pages()
    broken = [f"{page.relative_to(REPO)}: {target}"
              for page in pages for target in _LINK.findall(page.read_text())
              if not re.match(r"[a-z]+:", target) and not (page.parent / target).exists()]
    assert not broken, "\n".join(broken)
    assert "docs/results/bench.png" in (REPO / "README.md").read_text()


def test_source_paths_exist():
    """Every source file the docs name exists (the package redesign of issue 26 left
    ``splatgl/cameras/lens.py`` and ``shaders/lib/lens.glsl`` in the notes after they had gone)."""
    missing = [f"{page.relative_to(REPO)}: {name}" for page in _pages()
               for name in sorted(set(_SOURCE_PATH.findall(page.read_text())))
               if not _path_exists(name, page)]
    assert not missing, "paths the docs name that do not exist:\n" + "\n".join(missing)


def test_dotted_names_resolve():
    """Every ``splatgl.<module>.<name>`` the docs name imports and has that attribute (issue 26
    moved ``splatgl.cull_chunks.ChunkedCull`` to ``splatgl.order.chunks.ChunkedCull``)."""
    stale = [f"{page.relative_to(REPO)}: {name} ({problem})" for page in _pages()
             for name in sorted(set(_DOTTED.findall(page.read_text())))
             if (problem := _dotted_problem(name))]
    assert not stale, "names the docs use that do not resolve:\n" + "\n".join(stale)


def test_the_checks_catch_stale_names():
    """The two checks above refuse what the redesign left behind, and accept placeholders."""
    page = REPO / "README.md"
    assert not _path_exists("splatgl/cameras/lens.py", page)
    assert not _path_exists("shaders/lib/lens.glsl", page)
    assert _path_exists("shaders/cameras/<model>.glsl", page)
    assert not _path_exists("shaders/nothing/<model>.glsl", page)
    assert _path_exists("order/cull.py", page) and _path_exists("lib/camera.glsl", page)
    assert _SOURCE_PATH.findall("`shaders/stop_mark.vert/.frag`, https://x.org/a/b.py") == [
        "shaders/stop_mark.vert"]
    assert _dotted_problem("splatgl.order.chunks.ChunkedCull") is None
    assert _dotted_problem("splatgl.Camera.from_fov") is None
    assert "no 'cull_chunks'" in _dotted_problem("splatgl.cull_chunks.ChunkedCull")
    assert "no 'LodRenderer'" in _dotted_problem("splatgl.lod.selection.LodRenderer")


def test_the_readme_is_what_a_user_reads():
    """Issue 39 item 7: the README stays short (what it is, install, quick start, the commands, a
    Python example, links); the command reference, the design, the measurements and the test
    counts live in docs/.  Its Quick start is the two commands a new user runs, and the second
    is the one .ci/run runs."""
    readme = (REPO / "README.md").read_text()
    assert len(readme.splitlines()) <= 300
    quick = readme.split("## Quick start", 1)[1].split("\n## ", 1)[0]
    assert re.findall(r"```sh\n(.*?)```", quick, re.S) == [
        "pip install . && splatgl render -o demo.png\npip install '.[test]' && pytest\n"]
    assert "\npip install '.[test]' && pytest\n" in (REPO / ".ci" / "run").read_text()
    assert not re.search(r"\b\d[\d,]* tests\b", readme), "test counts belong nowhere in the README"
    for page in ("docs/cli.md", "docs/how-it-works.md", "docs/results/summary.md", "docs/api.md"):
        assert f"]({page})" in readme, f"the README links {page}"
