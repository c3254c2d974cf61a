"""Sphinx configuration of the meshmocap documentation.

Build: ``sphinx-build -W --keep-going docs docs/_build/html`` (``pip install -e ".[docs]"``).
``MESHMOCAP_DOCS_GALLERY`` sets how the gallery runs: ``full`` (default) runs every example,
``fast`` only the two that need no studio capture (seconds), ``off`` none (the pages then
show the code without its figures).
"""

from __future__ import annotations

import os
import warnings
from pathlib import Path

from docutils import nodes
from docutils.parsers.rst import Directive

import meshmocap

HERE = Path(__file__).resolve().parent

project = "meshmocap"
author = "meshmocap developers"
copyright = "meshmocap developers"
release = meshmocap.__version__
version = ".".join(release.split(".")[:2])

extensions = [
    "sphinx.ext.autodoc",
    "sphinx.ext.autosummary",
    "sphinx.ext.doctest",
    "sphinx.ext.viewcode",
    "numpydoc",
    "sphinx_gallery.gen_gallery",
]

templates_path = ["_templates"]
exclude_patterns = ["_build", "**.ipynb_checkpoints", "examples/README.rst"]
root_doc = "index"
nitpicky = True
# Type names in signatures that are not documented objects of their own (no intersphinx:
# the build machines have no network).
nitpick_ignore_regex = [
    (r"py:class", r"numpy\.typing\..*"),
    (r"py:class", r"(np|npt)\..*"),
    (r"py:class", r"optional"),
    # the standard library, numpy and scipy (no intersphinx without network)
    (r"py:.*", r"(os|pathlib|numpy|scipy|np|sklearn|dask|argparse)\..*"),
]

# -- autodoc / autosummary / numpydoc ----------------------------------------------------
autosummary_generate = True
autosummary_imported_members = False
autodoc_default_options = {"members": True, "member-order": "bysource"}
autodoc_typehints = "none"  # numpydoc's Parameters sections carry the types
autodoc_preserve_defaults = True
numpydoc_show_class_members = False
numpydoc_class_members_toctree = False
numpydoc_xref_param_type = False
numpydoc_attributes_as_param_list = True
# numpydoc's docstring checks that this code base keeps (a -W build fails on them): no
# undocumented public function or method (GL08), no documented parameter the signature
# lacks (PR02: text left inside a Parameters section renders as parameters), sections in
# order (GL07). Names in CamelCase (classes, and ``Literal`` aliases, which carry their
# documentation in a ``#:`` comment numpydoc does not see) are left out. The house style
# (types as shapes, ``V : (n, 3) float64``; no Examples or See Also everywhere) rules out
# the other checks.
numpydoc_validation_checks = {"GL07", "GL08", "PR02"}
numpydoc_validation_exclude = {r"\.__init__$", r"\.[A-Z][A-Za-z0-9]*$"}

# -- doctest -------------------------------------------------------------------------------
doctest_global_setup = "import numpy as np"

# -- sphinx-gallery ------------------------------------------------------------------------
_gallery = os.environ.get("MESHMOCAP_DOCS_GALLERY", "full")
sphinx_gallery_conf = {
    "examples_dirs": str(HERE / "examples"),
    "gallery_dirs": "auto_examples",
    "filename_pattern": {"full": r"/plot_", "fast": r"/plot_\d_(gait|latent)"}.get(_gallery, r"^$"),
    "plot_gallery": "True" if _gallery != "off" else "False",
    "download_all_examples": False,
    "remove_config_comments": True,
    "within_subsection_order": "FileNameSortKey",
    "matplotlib_animations": False,
    "image_scrapers": ("matplotlib",),
    "show_memory": False,
    "min_reported_time": 1,
}

# -- HTML ----------------------------------------------------------------------------------
html_theme = "pydata_sphinx_theme"
html_title = f"meshmocap {release}"
html_static_path = ["_static"]
html_theme_options = {
    "navigation_with_keys": False,
    "show_toc_level": 2,
    "secondary_sidebar_items": ["page-toc"],
}
html_show_sourcelink = False

warnings.filterwarnings("ignore", category=UserWarning, message="Matplotlib is currently using agg")


# -- short cross-references ----------------------------------------------------------------
# The docstrings name classes and functions of other modules by their short name
# (:class:`Motion`, :func:`track_sequence`). Resolve such a name to the one documented object
# whose full name ends with it, preferring the referring module's own package; an attribute
# of a documented class (:attr:`FrameResult.flags`, listed in its Attributes section) links
# to the class. Anything else stays a broken reference, and the -W build fails on it.
def _resolve_short_reference(app, env, node, contnode):
    if node.get("refdomain") != "py":
        return None
    py = env.get_domain("py")
    target = node["reftarget"].lstrip(".~")
    here = node.get("py:module") or ""
    for name in (target, target.rpartition(".")[0]):
        if not name:
            continue
        matches = [full for full in py.objects if full == name or full.endswith("." + name)]
        if len(matches) > 1:  # the kinds of object the role names (a function, not a module)
            kinds = set(py.objtypes_for_role(node["reftype"]) or ())
            matches = [m for m in matches if py.objects[m].objtype in kinds] or matches
        if len(matches) > 1:
            # the candidates nearest to the referring module
            def shared(full):
                a, b = full.split("."), here.split(".")
                n = 0
                while n < min(len(a), len(b)) and a[n] == b[n]:
                    n += 1
                return n

            best = max(shared(m) for m in matches)
            matches = [m for m in matches if shared(m) == best]
        if len(matches) == 1:
            objtype = py.objects[matches[0]].objtype
            role = {
                "class": "class",
                "exception": "exc",
                "function": "func",
                "method": "meth",
                "data": "data",
                "attribute": "attr",
                "module": "mod",
                "property": "attr",
            }.get(objtype, "obj")
            return py.resolve_xref(
                env, node["refdoc"], app.builder, role, matches[0], node, contnode
            )
    return None


# -- the command line reference ----------------------------------------------------------
# ``.. meshmocap-help::`` renders ``meshmocap --help`` and every command's ``--help`` from the
# parser itself, so the reference cannot drift from the code.
class MeshmocapHelp(Directive):
    def run(self):
        import argparse

        from meshmocap.cli import build_parser

        os.environ["COLUMNS"] = "90"  # argparse wraps to the terminal's width
        parser = build_parser()
        sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
        out = []
        for name, p in [("meshmocap", parser), *sub.choices.items()]:
            title = name if name == "meshmocap" else f"meshmocap {name}"
            section = nodes.section(ids=[nodes.make_id(f"cli-{name}")])
            section += nodes.title(text=title)
            text = p.format_help()
            section += nodes.literal_block(text, text)
            out.append(section)
        return out


def setup(app):
    app.connect("missing-reference", _resolve_short_reference)
    app.add_directive("meshmocap-help", MeshmocapHelp)
