"""Sphinx configuration of the kfnav documentation (``make docs`` builds it into build/docs)."""

import os
import re
import sys
import types
from pathlib import Path

# The Makefile copies docs/ to build/docs_src before building (with CHANGELOG.md as
# changelog.md), so that the API stubs autosummary writes stay under build/; KFNAV_ROOT names
# the repository either way.
ROOT = Path(os.environ.get("KFNAV_ROOT", Path(__file__).resolve().parents[1])).resolve()
os.environ["KFNAV_ROOT"] = str(ROOT)  # the tutorials' kernels run the CLI from here
sys.path.insert(0, str(ROOT))

# `cosim.__main__` runs the command line when imported: autosummary gets a stand-in.
sys.modules.setdefault("cosim.__main__", types.ModuleType(
    "cosim.__main__", "Entry point of ``python -m cosim`` (runs cosim.cli.main)."))

project = "kfnav"
author = "the kfnav authors"
copyright = "the kfnav authors, BSD-2-Clause"

extensions = [
    "myst_nb",                 # markdown pages and markdown notebooks (executed at build time)
    "sphinx.ext.autodoc",
    "sphinx.ext.autosummary",
    "sphinx.ext.mathjax",
    "sphinxarg.ext",           # the CLI reference, generated from cosim.cli.build_parser()
]

html_theme = "furo"
html_title = "kfnav"
templates_path = ["_templates"]
exclude_patterns = ["_build", "examples/*.py", "**.ipynb_checkpoints", "jupyter_execute"]
source_suffix = {".rst": "restructuredtext", ".md": "myst-nb"}

myst_enable_extensions = ["dollarmath", "colon_fence", "deflist"]
myst_heading_anchors = 3

# Tutorials are executed on every build, so their output is what the code does now.
nb_execution_mode = "force"
nb_execution_timeout = 300
nb_execution_raise_on_error = True
nb_execution_show_tb = True
nb_merge_streams = True

autosummary_generate = True
autosummary_imported_members = False
autodoc_default_options = {"members": True, "show-inheritance": False}
autodoc_member_order = "bysource"
autodoc_typehints = "none"
autodoc_preserve_defaults = True

_INLINE = re.compile(r"([*`|_\\])")


def _plain_docstring(app, what, name, obj, options, lines):
    """The project's docstrings are plain text, not reStructuredText: show them verbatim.

    The first paragraph (the summary autosummary takes) is kept as one escaped line; the
    rest becomes a literal block, so a docstring can never break the build.
    """
    if not lines:
        return
    text = [ln for ln in lines]
    first = []
    while text and text[0].strip():
        first.append(text.pop(0).strip())
    body = text
    while body and not body[0].strip():
        body.pop(0)
    summary = _INLINE.sub(r"\\\1", " ".join(first))
    out = [summary]
    if body:
        out += ["", "::", ""] + ["    " + ln for ln in body]
    lines[:] = out + [""]


def setup(app):
    app.connect("autodoc-process-docstring", _plain_docstring)
