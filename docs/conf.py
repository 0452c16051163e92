"""Sphinx configuration of gouge's documentation (`make docs`; warnings are errors, references checked)."""

import os
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(Path(__file__).parent / "_ext"))
os.environ.setdefault("MPLBACKEND", "Agg")

from gouge_cli import __version__  # noqa: E402

project = "gouge"
author = "the gouge developers"
copyright = "the gouge developers"
version = release = __version__

# sphinx-mathjax-offline copies MathJax into _static/ and points mathjax_path there: the equations
# render with no network (a cluster's login node, a laptop on a train)
extensions = ["myst_parser", "sphinx.ext.autodoc", "sphinx.ext.napoleon", "sphinx.ext.mathjax", "sphinx-mathjax-offline",
              "gouge_docs"]
myst_enable_extensions = ["dollarmath", "colon_fence", "deflist"]
myst_heading_anchors = 3
source_suffix = {".rst": "restructuredtext", ".md": "markdown"}
exclude_patterns = ["_build", "_generated", "figures", "Thumbs.db", ".DS_Store"]   # figures: data and included tables
nitpicky = True
# the Python API page documents gouge's own objects; types from other packages are not linked
nitpick_ignore_regex = [(r"py:.*", r"(numpy|np|h5py|pathlib|typing|collections|pydantic|typer|click|xarray|xr|pandas|pd)\..*"),
                        (r"py:class", r"(Path|ndarray|optional|array-like|callable)"),
                        # only gouge_cli.api is autodoc'd: its links into the internal layers stay text
                        (r"py:.*", r"gouge_cli\.(io|analysis|model|driver|kernels|workflows|plots|studies)\..*")]
autodoc_typehints = "signature"          # typed signatures on the API page (and return types of properties)
autodoc_member_order = "bysource"

html_theme = "furo"
html_title = f"gouge {__version__}"
html_static_path = []
html_show_sourcelink = False
smartquotes = False      # keep --option and "quotes" as typed
