"""Sphinx configuration of the skfem-nem documentation.

The theory pages are the project's markdown files (read by MyST); the API reference comes from
the numpydoc docstrings (napoleon); the gallery pages are generated from the examples'
docstrings by the local extension ``_ext/gallery.py``. Build with ``-W`` so that a broken
reference or a malformed docstring fails the build.
"""
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE / "_ext"))

project = "skfem-nem"
author = "the skfem-nem developers"
copyright = "the skfem-nem developers"
try:
    from skfem_nem import __version__ as release
except ImportError:  # the API pages will fail to build, and say why
    release = ""
version = release

extensions = [
    "sphinx.ext.autodoc",
    "sphinx.ext.autosummary",
    "sphinx.ext.napoleon",
    "sphinx.ext.viewcode",
    "sphinx.ext.mathjax",
    "myst_parser",
    "gallery",
]

source_suffix = {".rst": "restructuredtext", ".md": "markdown"}
root_doc = "index"
exclude_patterns = ["_build"]

# MyST: anchors for the headings the markdown pages link to (page.md#heading)
myst_heading_anchors = 3

# numpydoc docstrings
napoleon_google_docstring = False
napoleon_numpy_docstring = True
napoleon_use_rtype = False
autodoc_member_order = "bysource"
autodoc_typehints = "description"
autodoc_default_options = {"members": True}
autosummary_generate = False

# gallery: examples/*.py -> gallery/*.rst
gallery_examples_dir = str(HERE.parent / "examples")
gallery_figures_dir = str(HERE / "figures")
gallery_output_dir = str(HERE / "gallery")

# pydata-sphinx-theme: the page's own contents go into the left sidebar under the site
# navigation, so that the article takes the rest of the width (the default right-hand column
# leaves about 60 columns of code at 1280 px); _static/custom.css lets the article use that
# width and keeps code blocks and tables scrolling inside themselves
html_theme = "pydata_sphinx_theme"
html_title = f"skfem-nem {release}"
html_static_path = ["_static"]
html_css_files = ["custom.css"]
html_theme_options = {
    "navbar_align": "left",
    "secondary_sidebar_items": [],
    "show_toc_level": 2,
    "navigation_with_keys": False,
    "footer_start": ["copyright"],
    "footer_end": ["sphinx-version"],
}
html_sidebars = {
    "**": ["sidebar-nav-bs", "page-toc"],
    "index": [],
    "gallery/index": [],
}
