"""The examples gallery: one page per ``examples/*.py``, generated from the scripts themselves.

Each page shows the title and first paragraph of the example's module docstring, the figure the
example draws when one is kept under ``docs/figures`` (``<example stem>*.png``, or a name from
:data:`FIGURE_NAMES`), and the code as a literal include. The examples are not run: several take
minutes, and the figures in ``docs/figures`` are the ones the project keeps up to date.

The index is a grid of cards, one per example, grouped by subject (:data:`GROUPS`): the
example's first figure as a thumbnail over its one-line title. The cards are plain
reStructuredText containers styled by ``_static/custom.css``; the thumbnails are small copies of
the figures, written into ``gallery/thumbs/`` when the builder starts.

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

#: the gallery index's groups, in order: (heading, example stems); an example in no group is
#: shown under "More examples" at the end
GROUPS = [
    ("Interpolation and the basis functions",
     ["ex01_interpolation", "ex24_scattered_interpolation", "ex12_smoothing", "ex13_interfaces"]),
    ("NEM against P1 and P2 finite elements",
     ["ex02_poisson", "ex04_nem_vs_fem", "ex14_point_source", "ex19_adaptive_lshape",
      "ex03_cantilever", "ex18_elastic_modes", "ex17_heat", "ex15_subdomains",
      "ex16_integral_condition", "ex21_quadratic"]),
    ("Stokes flow and rheology",
     ["ex07_solcx", "ex08_sinking_block", "ex09_viscoelastic_buildup", "ex11_prandtl_punch"]),
    ("Evolving meshes",
     ["ex05_shear_flow", "ex20_local_update", "ex10_lagrangian_fem_fails"]),
    ("3D", ["ex06_poisson_3d", "ex22_settling_sphere", "ex23_sinking_sphere_3d"]),
]

#: width in pixels of the thumbnails on the gallery index
THUMB_WIDTH = 480


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


def _card(path: Path, figures_dir: Path, output_dir: Path) -> str:
    """One card of the index: the thumbnail of the example's first figure and its title."""
    title, _ = example_summary(path)
    lines = ["   .. container:: nem-card\n"]
    figures = example_figures(path.stem, figures_dir)
    if figures:
        lines.append(f"      .. image:: thumbs/{figures[0].name}\n"
                     f"         :target: {path.stem}.html\n"
                     f"         :alt: figure of {path.name}\n")
    text = title.replace("``", "").replace("`", "")  # no markup inside the role's text
    lines.append(f"      :doc:`{text} <{path.stem}>`\n")
    return "\n".join(lines)


def gallery_groups(examples: list[Path]) -> list[tuple[str, list[Path]]]:
    """The examples in the index's groups (:data:`GROUPS`), the others in a last group."""
    by_stem = {p.stem: p for p in examples}
    groups = [(heading, [by_stem[s] for s in stems if s in by_stem])
              for heading, stems in GROUPS]
    grouped = {s for _, stems in GROUPS for s in stems}
    rest = [p for p in examples if p.stem not in grouped]
    if rest:
        groups.append(("More examples", rest))
    return [(heading, members) for heading, members in groups if members]


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
             "Runnable scripts in ``examples/`` of the repository. Click a picture to see what "
             "the example computes, its figure and its code.\n"]
    for heading, members in gallery_groups(examples):
        lines.append(_heading(heading, "-"))
        lines.append(".. container:: nem-gallery\n")
        lines += [_card(p, figures_dir, output_dir) for p in members]
    lines.append(".. toctree::\n   :hidden:\n   :maxdepth: 1\n")
    lines += [f"   {p.stem}" for p in examples]
    pages["index.rst"] = "\n".join(lines) + "\n"
    return pages


def write_thumbnails(examples_dir: Path, figures_dir: Path, output_dir: Path) -> None:
    """Small copies of each example's first figure in ``output_dir/thumbs`` (a thumbnail is
    rewritten only when its figure is newer)."""
    from matplotlib import image

    thumbs = Path(output_dir) / "thumbs"
    thumbs.mkdir(parents=True, exist_ok=True)
    for path in sorted(Path(examples_dir).glob("*.py")):
        figures = example_figures(path.stem, figures_dir)
        if not figures:
            continue
        target = thumbs / figures[0].name
        if target.exists() and target.stat().st_mtime >= figures[0].stat().st_mtime:
            continue
        width = image.imread(figures[0]).shape[1]
        image.thumbnail(str(figures[0]), str(target), scale=min(1.0, THUMB_WIDTH / width))


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
    write_thumbnails(cfg.gallery_examples_dir, cfg.gallery_figures_dir, out)


def setup(app):
    here = Path(app.confdir)
    app.add_config_value("gallery_examples_dir", str(here.parent / "examples"), "env")
    app.add_config_value("gallery_figures_dir", str(here / "figures"), "env")
    app.add_config_value("gallery_output_dir", str(here / "gallery"), "env")
    app.connect("builder-inited", write_gallery)
    return {"version": "1", "parallel_read_safe": True, "parallel_write_safe": True}
