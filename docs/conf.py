"""Sphinx configuration of the sliders documentation.

Build (the test suite does the same, tests/test_docs.py):

    .venv/bin/python -m sphinx -W --keep-going -b html docs docs/_build/html

Sphinx rather than MkDocs: the API reference comes from the numpydoc docstrings
through autodoc/autosummary (as for NumPy, SciPy and xarray), the tutorial
notebook is executed during the build by myst-nb, and both read the same
Markdown (MyST) pages.  The reference is generated over the package namespace
``sliders`` and whatever modules it holds (autosummary, recursive), so it
follows the package when modules move.
"""

import os
import pathlib
import shutil
import sys

import sliders

project = "sliders"
author = "the sliders developers"
release = version = sliders.__version__
copyright = "2026, the sliders developers"

extensions = [
    "myst_nb",                       # MyST Markdown pages and executed notebooks
    "sphinx.ext.autodoc",
    "sphinx.ext.autosummary",
    "sphinx.ext.mathjax",
    "numpydoc",
]

exclude_patterns = ["_build", "figures/README.md", "**.ipynb_checkpoints"]
templates_path = ["_templates"]
suppress_warnings = ["myst.header"]  # included files (REPRODUCTION.md ...) start at their own level

# MyST: $...$ maths, heading anchors for links like page.md#section
myst_enable_extensions = ["dollarmath", "colon_fence"]
myst_heading_anchors = 3

# The tutorial is executed at every build (it takes well under a minute); an
# error in a cell fails the build.
nb_execution_mode = os.environ.get("SLIDERS_DOCS_EXECUTE", "force")  # "off": text only
nb_execution_timeout = 300
nb_execution_raise_on_error = True
nb_execution_show_tb = True

# API reference: numpydoc docstrings, one page per public module.
autosummary_generate = True
# The stubs are rebuilt from the package on every build: stale ones (a module
# that moved, as sliders.conventions into sliders.io) would break the -W build.
shutil.rmtree(os.path.join(os.path.dirname(os.path.abspath(__file__)), "generated"),
              ignore_errors=True)
autosummary_ignore_module_all = False
# The two-line modules that keep `python -m sliders.ensemble` & co. working
# (sliders/_forward.py) are aliases of modules documented in their layer: not twice.
_package = os.path.dirname(sliders.__file__)
autosummary_context = {"forwarders": sorted(
    "sliders." + name[:-3] for name in os.listdir(_package)
    if name.endswith(".py")
    and "forward(__name__" in pathlib.Path(_package, name).read_text())}
autodoc_default_options = {}
autodoc_typehints = "none"            # the numpydoc sections say the types and units
numpydoc_show_class_members = False
numpydoc_class_members_toctree = False
numpydoc_xref_param_type = False

html_theme = "alabaster"
html_title = f"sliders {release}"
html_static_path = ["_static"]
html_css_files = ["sliders.css"]  # tables and code blocks wrap to the page's width
html_theme_options = {"page_width": "1100px", "body_max_width": "none"}


def _numpydoc_compiles_its_template_once():
    """numpydoc (1.11) builds a new Jinja environment for every docstring and compiles its
    docstring template again in each: half the build's time.  Every environment it makes
    here hands out the template compiled first (the loader and the template are the same)."""
    from numpydoc import docscrape_sphinx

    class OneCompile(docscrape_sphinx.SandboxedEnvironment):
        compiled: dict = {}

        def get_template(self, name, *args, **kwargs):
            if name not in self.compiled:
                self.compiled[name] = super().get_template(name, *args, **kwargs)
            return self.compiled[name]

    docscrape_sphinx.SandboxedEnvironment = OneCompile


_numpydoc_compiles_its_template_once()
