"""Sphinx configuration of the fdia_env documentation site (``make docs``)."""

from __future__ import annotations

import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))
sys.path.insert(0, str(HERE / "_ext"))

import fdia_env  # noqa: E402

project = "fdia_env"
author = "fdia_env developers"
copyright = "the fdia_env developers (MIT license)"  # the footer: "Copyright © ..."
release = fdia_env.__version__
extensions = [
    "myst_parser",
    "sphinx.ext.autodoc",
    "sphinx.ext.napoleon",
    "sphinx.ext.mathjax",
    "sphinx.ext.viewcode",
    "generate_pages",  # env pages, render images and API pages, written at build time
    "local_links",  # viewcode's back-links fixed; every internal link and anchor checked
]
source_suffix = {".md": "markdown", ".rst": "restructuredtext"}
exclude_patterns = ["_build", "README.md"]
myst_enable_extensions = ["dollarmath", "colon_fence"]
myst_heading_anchors = 3
napoleon_google_docstring = True
napoleon_numpy_docstring = False
napoleon_use_ivar = True  # "Attributes:" as fields: properties are documented once
autodoc_member_order = "bysource"
autodoc_typehints = "description"
autodoc_default_options = {"show-inheritance": True}
suppress_warnings = ["myst.header"]
html_theme = "furo"
html_title = f"fdia_env {release}"
html_static_path = ["_static"]
