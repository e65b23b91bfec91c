"""The code in the documentation fits the page: no sideways scrolling for a reader.

The limit, 100 columns, is what a code block of the theme (pydata-sphinx-theme with the
settings of docs/conf.py and docs/_static/custom.css) shows without scrolling in a browser
window 1280 px wide: measured in Chromium, the block is 851 px wide inside its padding and a
character of its monospace font (13.6 px) is 8.18 px wide, so 104 columns fit; 100 leaves a
margin for other monospace fonts. It is also ruff's line length, so the examples that the
gallery includes fit as well.
"""
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
DOCS = ROOT / "docs"
LIMIT = 100
PAGES = sorted(DOCS.glob("*.md")) + sorted((DOCS / "howto").glob("*.md")) + [ROOT / "README.md"]
#: MyST directives whose body is code; other directives (toctree, math, figure) are not code
CODE_DIRECTIVES = {"code-block", "code", "sourcecode", "code-cell"}
FENCE = re.compile(r"^(\s*)(`{3,}|~{3,})\s*(\{([\w-]+)\})?")


def code_lines(path):
    """(line number, line) of every line inside a fenced code block of a markdown file."""
    lines = path.read_text(encoding="utf-8").splitlines()
    out, fence, is_code = [], None, False
    for number, line in enumerate(lines, 1):
        m = FENCE.match(line)
        if fence is None:
            if m:
                fence = m.group(2)
                is_code = m.group(4) is None or m.group(4) in CODE_DIRECTIVES
        elif m and m.group(2)[0] == fence[0] and len(m.group(2)) >= len(fence) \
                and not line.strip()[len(m.group(2)):].strip():
            fence = None
        elif is_code:
            out.append((number, line))
    return out


def test_pages_have_code():
    assert sum(len(code_lines(p)) for p in PAGES) > 100


@pytest.mark.parametrize("path", PAGES, ids=lambda p: str(p.relative_to(ROOT)))
def test_code_fits_the_page(path):
    wide = [f"{path.name}:{n}: {len(line)} columns" for n, line in code_lines(path)
            if len(line.expandtabs()) > LIMIT]
    assert not wide, f"code lines wider than {LIMIT} columns:\n" + "\n".join(wide)


def test_a_wide_line_is_found(tmp_path):
    page = tmp_path / "page.md"
    page.write_text("text " * 40 + "\n\n```python\n" + "x = 1  # " + "y" * 100 + "\n```\n\n"
                    "```{math}\n" + "a" * 200 + "\n```\n")
    assert [n for n, line in code_lines(page) if len(line) > LIMIT] == [4]
