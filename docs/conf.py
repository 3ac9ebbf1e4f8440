"""Sphinx configuration of lipsync's documentation site (``make docs``).

Why Sphinx, not MkDocs: the docstrings are numpydoc (the project's standard), which
Sphinx's ``numpydoc`` extension renders as written; autodoc imports the real objects, so the
API reference lists exactly what ``import lipsync`` exposes; and with ``-W --keep-going -n``
(nitpicky) every broken cross-reference, missing page or bad anchor fails the build.
MyST reads the Markdown pages (the feature branches write Markdown), furo is a clean,
offline theme (no CDN, no web fonts fetched at build or view time).

Three pages are generated at build time by ``docs/_ext/generated.py`` (into
``docs/_generated/``, not committed): the CLI reference from the argparse parsers, the API
reference from ``lipsync._EXPORTS`` and the public submodules, and the benchmark tables
from ``bench/results.json``.
"""

from __future__ import annotations

import os
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, "_ext"))

project = "lipsync"
author = "the lipsync authors"
copyright = "the lipsync authors, MIT licence"

extensions = [
    "myst_parser",
    "sphinx.ext.autodoc",
    "numpydoc",
    "generated",
]

source_suffix = {".md": "markdown", ".rst": "restructuredtext"}
root_doc = "index"
exclude_patterns = ["_build", "Thumbs.db", ".DS_Store", "_ext"]

# MyST: heading anchors so that [text](page.md#a-heading) links are checked.
myst_heading_anchors = 3
myst_enable_extensions = ["colon_fence"]

# numpydoc: no class members table (autodoc lists the documented members), no xref of types
# (types in docstrings are prose such as "array (H, W, 3)", not importable names).
numpydoc_show_class_members = False
numpydoc_xref_param_type = False
numpydoc_validation_checks: set = set()
autodoc_member_order = "bysource"
autodoc_typehints = "none"   # the numpydoc sections say the types in words
autodoc_default_options = {}

# Option names stay as typed (--lang, not an en dash).
smartquotes = False

html_theme = "furo"
html_title = "lipsync"
html_static_path: list = []
html_show_sourcelink = False
# Offline: nothing is fetched when building or viewing (no intersphinx, no external fonts).
# Pygments' GDScript lexer trips on Godot 4's annotations (@export); highlighting only.
suppress_warnings = ["myst.header", "misc.highlighting_failure"]
