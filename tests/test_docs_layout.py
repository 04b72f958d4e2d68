"""docs/ holds the design notes (.md) and the pictures they show; raw benchmark output (JSON,
JSONL, CSV, TXT, measurement plots, generated tables) lives in docs/results/.  Every relative
link of README.md and the notes points at a file that exists."""

from __future__ import annotations

import re
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
DOCS = REPO / "docs"
_LINK = re.compile(r"\]\(([^)#\s]+)(?:#[^)]*)?\)")


def test_raw_output_lives_in_results():
    loose = sorted(p.name for p in DOCS.iterdir()
                   if p.is_file() and p.suffix not in (".md", ".png"))
    assert not loose, f"raw output belongs in docs/results/: {loose}"
    assert any((DOCS / "results").glob("*.json")), "the measurements moved, not vanished"


def test_relative_links_resolve():
    pages = [REPO / "README.md", *sorted(DOCS.rglob("*.md"))]
    broken = [f"{page.relative_to(REPO)}: {target}"
              for page in pages for target in _LINK.findall(page.read_text())
              if not re.match(r"[a-z]+:", target) and not (page.parent / target).exists()]
    assert not broken, "\n".join(broken)
    assert "docs/results/bench.png" in (REPO / "README.md").read_text()
