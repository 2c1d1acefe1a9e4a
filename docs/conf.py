"""Sphinx configuration of the rrr-pin documentation (``make docs``).

Builds the API reference from the numpydoc docstrings (autosummary + numpydoc), the README and the
Markdown pages of ``docs/`` (MyST), and a gallery of ``scripts/`` (sphinx-gallery), which runs
the two example scripts with small settings (see ``gallery.py``).
"""

import sys
from pathlib import Path

import rrr_pin

DOCS = Path(__file__).resolve().parent
sys.path.insert(0, str(DOCS))  # gallery.py: reset_argv and the PNG scraper, by qualified name

project = "rrr-pin"
author = "rrr-pin developers"
release = rrr_pin.__version__
version = release

extensions = [
    "sphinx.ext.autodoc",
    "sphinx.ext.autosummary",
    "sphinx.ext.mathjax",
    "numpydoc",
    "myst_parser",
    "sphinx_gallery.gen_gallery",
]

source_suffix = {".rst": "restructuredtext", ".md": "markdown"}
templates_path = ["_templates"]
# api/ and gallery/ are generated at build time (autosummary stubs, sphinx-gallery pages).
exclude_patterns = ["_build", "gallery/*.ipynb", "gallery/*.py"]

# autosummary writes one page per module (docs/api/, git-ignored) from _templates/autosummary.
autosummary_generate = True
autosummary_imported_members = False
autodoc_default_options = {"member-order": "bysource"}
# The lazy top-level names (rrr_pin.__getattr__) are documented in their modules only.
autodoc_typehints = "none"  # numpydoc's Parameters sections carry the types, with shapes and units

# numpydoc renders the docstrings; class members are listed by autodoc, not a second time.
numpydoc_show_class_members = False
numpydoc_class_members_toctree = False
numpydoc_xref_param_type = False
# A References section is the bibliography of its object: numpydoc renames its entries
# (R<hash>-1, ...) and Sphinx warns for each one the text does not cite with ``[1]_``.
suppress_warnings = ["ref.citation"]

# No intersphinx: a failed inventory fetch is a warning, and the build runs with -W.

myst_heading_anchors = 3

sphinx_gallery_conf = {
    "examples_dirs": ["../scripts"],
    "gallery_dirs": ["gallery"],
    # Executed: the two example scripts (small settings from gallery.reset_argv).
    # Listed, not executed: bench.py (minutes) and codegen.py (a developer tool).
    "filename_pattern": r"/(simulate_nominal|uncertain_study)\.py$",
    "reset_argv": "gallery.reset_argv",
    "image_scrapers": ("gallery.png_scraper",),
    "download_all_examples": False,
    "plot_gallery": "True",
    "abort_on_example_error": True,
    "within_subsection_order": "gallery.ExamplesFirst",
    "min_reported_time": 1,
}

html_theme = "alabaster"
html_title = f"rrr-pin {release}"
html_static_path = []
