"""docs/cli.md is the command reference, kept true to the parsers (issue 39 item 7).

Each command (and each sub-command of ``path`` and ``conformance``) has a section in
docs/cli.md under a heading that starts with its command line (``## `splatgl render ...` ``).
Every option its parser (:func:`splatgl.cli.build_parser`) takes is named in that section or in
a shared option group the section links to (``[camera options](#camera-options)``), and every
option the page names is one the parser has: in a command's own section, one of that command's;
in a code span or example line that starts ``splatgl CMD``, one of CMD's; anywhere else, one of
some command's.  An option added to a command without its line in the reference, or a line left
behind by an option that went, fails here.
"""

from __future__ import annotations

import argparse
import re
from pathlib import Path

from splatgl.cli import build_parser

REPO = Path(__file__).resolve().parents[2]
PAGE = REPO / "docs" / "cli.md"

#: The page's shared option groups (the anchor of their heading) and the argument group of the
#: parsers each stands for (``add_argument_group`` titles in ``splatgl/commands/``).
GROUPS = {
    "camera-options": "camera",
    "rendering-options": "rendering",
    "running-on-more-processes": "running on more processes or machines",
}

_HEADING = re.compile(r"^(#{1,6}) +(.*)$", re.M)
#: A long option as written in prose: ``--lod-threshold``, or a family ``--ray-*``.
_LONG = re.compile(r"(?<![\w-])--[a-z][a-z0-9]*(?:-[a-z0-9]+)*(?:-\*)?")
#: A command line written out: a code span starting ``splatgl``, or such a line in a fenced block.
_SPAN = re.compile(r"`(splatgl [^`]*)`")
_FENCE = re.compile(r"^```[^\n]*\n(.*?)^```", re.M | re.S)


def _commands() -> dict[tuple[str, ...], argparse.ArgumentParser]:
    """Every command and sub-command parser by its words: ``("path", "orbit")``."""
    found: dict[tuple[str, ...], argparse.ArgumentParser] = {}

    def walk(parser: argparse.ArgumentParser, words: tuple[str, ...]) -> None:
        for action in parser._actions:
            if isinstance(action, argparse._SubParsersAction):
                for name, sub in action.choices.items():
                    found[words + (name,)] = sub
                    walk(sub, words + (name,))

    walk(build_parser(), ())
    return found


COMMANDS = _commands()
#: The options of ``splatgl`` itself, before any command (``splatgl --version``).
TOP = {o for a in build_parser()._actions for o in a.option_strings if o not in ("-h", "--help")}
#: Commands that run (``path`` and ``conformance`` only choose a sub-command).
LEAVES = {words: p for words, p in COMMANDS.items()
          if not any(isinstance(a, argparse._SubParsersAction) for a in p._actions)}


def _options(parser: argparse.ArgumentParser, group: str | None = None) -> set[str]:
    actions = parser._actions if group is None else next(
        (g._group_actions for g in parser._action_groups if g.title == group), [])
    return {o for a in actions for o in a.option_strings if o not in ("-h", "--help")}


def _command_of(text: str) -> tuple[str, ...] | None:
    """The longest run of words after ``splatgl`` that names a command, or None."""
    words = text.split()[1:]
    best = None
    for k in range(1, len(words) + 1):
        if tuple(words[:k]) in COMMANDS:
            best = tuple(words[:k])
    return best


def _anchor(title: str) -> str:
    """GitHub's anchor for a heading."""
    return re.sub(r"[^\w\- ]", "", title.strip().lower()).replace(" ", "-")


def _sections(text: str) -> list[tuple[str, int, str]]:
    """(title, level, body) per heading; a body ends at the next heading of its level or above,
    or at the next command heading."""
    heads = list(_HEADING.finditer(text))
    out = []
    for i, h in enumerate(heads):
        level, end = len(h.group(1)), len(text)
        for later in heads[i + 1:]:
            if len(later.group(1)) <= level or _command_heading(later.group(2)):
                end = later.start()
                break
        out.append((h.group(2), level, text[h.end():end]))
    return out


def _command_heading(title: str) -> tuple[str, ...] | None:
    m = re.match(r"`(splatgl [^`]*)`", title)
    return _command_of(m.group(1)) if m else None


def _named(text: str) -> set[str]:
    return set(_LONG.findall(text))


def _known(name: str, options: set[str]) -> bool:
    if name.endswith("-*"):
        return any(o.startswith(name[:-1]) for o in options)
    return name in options


def _command_lines(text: str) -> list[str]:
    fenced = [line for block in _FENCE.findall(text) for line in block.splitlines()
              if line.startswith("splatgl ")]
    return _SPAN.findall(text) + fenced


def _without_command_lines(text: str) -> str:
    text = _FENCE.sub(lambda m: "\n".join(line for line in m.group(0).splitlines()
                                          if not line.startswith("splatgl ")), text)
    return _SPAN.sub(" ", text)


def _misused(line: str) -> list[str]:
    """What is wrong with a written-out ``splatgl ...`` line: no such command, or options
    the command (or, for ``path``, any of its sub-commands) does not take."""
    words = _command_of(line)
    if words is None:
        named = _named(line)
        return [] if named and named <= TOP and len(line.split()) == 2 else ["no such command"]
    options = set().union({"--help"}, *(_options(p) for w, p in LEAVES.items()
                                        if w[:len(words)] == words))
    return [o for o in sorted(_named(line)) if not _known(o, options)]


def _page() -> str:
    return PAGE.read_text()


def _documented() -> dict[tuple[str, ...], str]:
    """Each command's text on the page: its section and the shared groups the section links."""
    sections = _sections(_page())
    groups = {_anchor(t): body for t, _, body in sections if _anchor(t) in GROUPS}
    out: dict[tuple[str, ...], str] = {}
    for title, _, body in sections:
        words = _command_heading(title)
        if words is None:
            continue
        assert words not in out, f"two sections for splatgl {' '.join(words)}"
        linked = [groups[a] for a in re.findall(r"\]\(#([\w-]+)\)", body) if a in groups]
        out[words] = "\n".join([title, body, *linked])
    return out


def test_every_command_has_a_section():
    documented = _documented()
    missing = [" ".join(w) for w in LEAVES if w not in documented]
    assert not missing, f"commands without a section in docs/cli.md: {missing}"
    parents = [" ".join(w) for w in documented if w not in LEAVES]
    assert not parents, f"sections for commands that only pick a sub-command: {parents}"


def test_every_option_is_documented_under_its_command():
    documented = _documented()
    missing = []
    for words, parser in LEAVES.items():
        text = documented.get(words, "")
        for option in sorted(_options(parser)):
            pattern = (rf"(?<![\w-]){re.escape(option)}(?![\w-])" if option.startswith("--")
                       else rf"`{re.escape(option)}[`, ]")   # -o: as `-o, --output FILE`
            if not re.search(pattern, text):
                missing.append(f"splatgl {' '.join(words)} {option}")
    assert not missing, "options missing from docs/cli.md:\n" + "\n".join(missing)


def test_the_page_names_no_option_a_command_lacks():
    page = _page()
    every = set().union({"--help"}, TOP, *(_options(p) for p in LEAVES.values()))
    wrong = []
    # Written-out command lines, anywhere on the page.
    wrong += [f"{line!r}: {problem}" for line in _command_lines(page) for problem in _misused(line)]
    # Each command's own section (without its written-out command lines).
    for title, _, body in _sections(page):
        words = _command_heading(title)
        if words in LEAVES:
            options = _options(LEAVES[words])
            wrong += [f"section splatgl {' '.join(words)}: {o}"
                      for o in sorted(_named(_without_command_lines(body))) if not _known(o, options)]
    # Shared groups: options of the parsers' group; elsewhere: options of some command.
    for title, _, body in _sections(page):
        group = GROUPS.get(_anchor(title))
        if group is not None:
            options = set().union(*(_options(p, group) for p in LEAVES.values()))
            rows = set(re.findall(r"^\| `(--[\w-]+)", body, re.M))
            wrong += [f"group {title}: {o}" for o in sorted(rows) if o not in options]
    wrong += [f"page: {o}" for o in sorted(_named(_without_command_lines(page)))
              if not _known(o, every)]
    assert not wrong, "options docs/cli.md names that the parsers lack:\n" + "\n".join(wrong)


def test_command_lines_in_every_page_use_real_options():
    """A ``splatgl CMD ...`` written out in the README or any note takes only options CMD has
    (prose that merely starts with the word splatgl, ``splatgl frame {...}``, is no command)."""
    pages = [REPO / "README.md", *sorted((REPO / "docs").rglob("*.md"))]
    wrong = [f"{page.relative_to(REPO)}: {line!r}: {problem}" for page in pages
             for line in _command_lines(page.read_text()) if _command_of(line)
             for problem in _misused(line)]
    assert not wrong, "command lines with options their command lacks:\n" + "\n".join(wrong)


def test_shared_groups_match_the_parsers():
    """A shared group lists exactly its parser group's options, and a command links it only
    when its parser has that group."""
    sections = _sections(_page())
    anchors = {_anchor(t): body for t, _, body in sections}
    for anchor, group in GROUPS.items():
        assert anchor in anchors, f"docs/cli.md has no section #{anchor}"
        options = set().union(*(_options(p, group) for p in LEAVES.values()))
        rows = set(re.findall(r"(?<![\w-])--[a-z][\w-]*", "\n".join(
            line for line in anchors[anchor].splitlines() if line.startswith("| `"))))
        assert options <= rows, f"#{anchor} lacks {sorted(options - rows)}"
    for title, _, body in sections:
        words = _command_heading(title)
        if words in LEAVES:
            for anchor in set(re.findall(r"\]\(#([\w-]+)\)", body)) & set(GROUPS):
                assert _options(LEAVES[words], GROUPS[anchor]), (
                    f"splatgl {' '.join(words)} links #{anchor} but has no such options")


def test_links_into_the_pages_land_on_a_heading():
    """Links with an anchor between the README and the pages this item wrote (``cli.md#...``,
    ``#camera-options``) name a heading that exists: a renamed command heading fails here."""
    pages = [REPO / "README.md", PAGE, *(REPO / "docs").glob("*.md"), *(REPO / "docs/results").glob("*.md")]
    anchors = {p.resolve(): {_anchor(t) for t, _, _ in _sections(p.read_text())} for p in pages}
    checked = {PAGE.resolve(), (REPO / "docs/api.md").resolve(), (REPO / "docs/how-it-works.md").resolve(),
               (REPO / "docs/testing.md").resolve(), (REPO / "docs/results/summary.md").resolve(),
               (REPO / "README.md").resolve()}
    broken = []
    for page in pages:
        for target, anchor in re.findall(r"\]\(([^)#\s]*)#([^)\s]+)\)", page.read_text()):
            dest = (page.parent / target).resolve() if target else page.resolve()
            if dest in checked and anchor not in anchors.get(dest, set()):
                broken.append(f"{page.relative_to(REPO)}: {target}#{anchor}")
    assert not broken, "links to headings that do not exist:\n" + "\n".join(broken)


def test_the_checks_catch_a_stale_page():
    """The helpers see what they must: a family, an option in a command line, section bounds."""
    assert _known("--ray-*", _options(LEAVES[("render",)]))
    assert not _known("--lod-*", _options(LEAVES[("info",)]))
    assert _command_of("splatgl path orbit scene.ply -o p.json") == ("path", "orbit")
    assert _command_of("splatgl nothing --x") is None
    assert _misused("splatgl --version") == [] and _misused("splatgl --version x") != []
    assert _misused("splatgl info scene.ply --json --lod-budget 3") == ["--lod-budget"]
    assert _command_lines("a `splatgl info --stats` b\n```sh\nsplatgl lod s -o t\nother\n```\n") == [
        "splatgl info --stats", "splatgl lod s -o t"]
    assert _named("`--json -`, `--lod-*` and -o, not ---x or a--b") == {"--json", "--lod-*"}
    text = "## `splatgl info SCENE`\nA `--stats`.\n### More\nB\n## Other\nC\n"
    assert [(t, b.strip()) for t, _, b in _sections(text)] == [
        ("`splatgl info SCENE`", "A `--stats`.\n### More\nB"), ("More", "B"), ("Other", "C")]
    assert _anchor("Running on more processes") == "running-on-more-processes"
