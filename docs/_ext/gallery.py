"""The examples gallery: one page per ``examples/*.py``, generated from the scripts themselves.

Each page shows the title and first paragraph of the example's module docstring, the figure the
example draws when one is kept under ``docs/figures`` (``<example stem>*.png``, or a name from
:data:`FIGURE_NAMES`), and the code as a literal include. The examples are not run: several take
minutes, and the figures in ``docs/figures`` are the ones the project keeps up to date.

The pages are written into ``gallery/`` of the documentation source when the builder starts
(only files whose text changed are rewritten, so incremental builds stay incremental).
:func:`gallery_pages` builds the text without Sphinx, for the tests.
"""
from __future__ import annotations

import ast
import os
from pathlib import Path

#: figures whose name does not start with the example's stem
FIGURE_NAMES = {"ex12_smoothing": ["smoothing_cells.png"]}


def example_summary(path: Path) -> tuple[str, str]:
    """The title (first line) and first paragraph of an example's module docstring.

    A paragraph that does not end a sentence (it introduces a formula or a list) runs on
    into the blocks after it, up to the end of a sentence.

    Raises
    ------
    ValueError
        If the example has no module docstring.
    """
    doc = ast.get_docstring(ast.parse(Path(path).read_text(encoding="utf-8")))
    if not doc:
        raise ValueError(f"example {Path(path).name} has no module docstring")
    title, *paragraphs = [p.strip("\n") for p in doc.split("\n\n") if p.strip()]
    summary = []
    for p in paragraphs:
        summary.append(p)
        if p.rstrip().endswith("."):
            break
    return title.strip().rstrip(".").replace("\n", " "), "\n\n".join(summary)


def example_figures(stem: str, figures_dir: Path) -> list[Path]:
    """The figures kept for an example: ``<stem>*.png`` and any named in FIGURE_NAMES."""
    figures_dir = Path(figures_dir)
    found = sorted(figures_dir.glob(f"{stem}*.png"))
    found += [figures_dir / name for name in FIGURE_NAMES.get(stem, [])]
    return found


def _heading(text: str, char: str) -> str:
    return f"{text}\n{char * len(text)}\n"


def example_page(path: Path, figures_dir: Path, output_dir: Path) -> str:
    """The reStructuredText of one example's page (paths relative to ``output_dir``)."""
    path = Path(path)
    title, paragraph = example_summary(path)
    parts = [f".. _gallery-{path.stem}:\n", _heading(title, "="), paragraph + "\n"]
    for fig in example_figures(path.stem, figures_dir):
        rel = os.path.relpath(fig, output_dir).replace(os.sep, "/")
        parts.append(f".. figure:: {rel}\n   :width: 100%\n   :alt: figure of {path.name}\n")
    rel_code = os.path.relpath(path, output_dir).replace(os.sep, "/")
    parts.append(f"Run it with ``python examples/{path.name}``.\n")
    parts.append(f".. literalinclude:: {rel_code}\n   :language: python\n   :caption: "
                 f"examples/{path.name}\n")
    return "\n".join(parts)


def gallery_pages(examples_dir: Path, figures_dir: Path, output_dir: Path) -> dict[str, str]:
    """All gallery pages, ``{file name: reStructuredText}``: ``index.rst`` and one per example.

    Raises
    ------
    ValueError
        If ``examples_dir`` holds no example scripts.
    """
    examples = sorted(Path(examples_dir).glob("*.py"))
    if not examples:
        raise ValueError(f"no example scripts (*.py) in {examples_dir}")
    pages = {f"{p.stem}.rst": example_page(p, figures_dir, output_dir) for p in examples}
    lines = [_heading("Examples gallery", "="),
             "Runnable scripts in ``examples/`` of the repository, from scattered-data "
             "interpolation to the sinking plate on a classical mesh. Each page shows what the "
             "example computes, the figure it draws (where one is kept) and its code.\n",
             ".. toctree::\n   :maxdepth: 1\n"]
    lines += [f"   {p.stem}" for p in examples]
    pages["index.rst"] = "\n".join(lines) + "\n"
    return pages


def write_gallery(app) -> None:
    """Write the gallery pages into the source tree (``builder-inited``); pages of examples
    that no longer exist are removed."""
    cfg = app.config
    out = Path(cfg.gallery_output_dir)
    out.mkdir(parents=True, exist_ok=True)
    pages = gallery_pages(cfg.gallery_examples_dir, cfg.gallery_figures_dir, out)
    for stale in set(p.name for p in out.glob("*.rst")) - set(pages):
        (out / stale).unlink()
    for name, text in pages.items():
        target = out / name
        if not target.exists() or target.read_text(encoding="utf-8") != text:
            target.write_text(text, encoding="utf-8")


def setup(app):
    here = Path(app.confdir)
    app.add_config_value("gallery_examples_dir", str(here.parent / "examples"), "env")
    app.add_config_value("gallery_figures_dir", str(here / "figures"), "env")
    app.add_config_value("gallery_output_dir", str(here / "gallery"), "env")
    app.connect("builder-inited", write_gallery)
    return {"version": "1", "parallel_read_safe": True, "parallel_write_safe": True}
