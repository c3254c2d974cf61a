"""The public modules of meshmocap, by layer, for the API reference (``docs/api/index.rst``).

``python docs/api_modules.py`` rewrites ``docs/api/index.rst``; ``docs/test_docs.py`` fails
when a public module (no part of its name starts with ``_``) is missing from it.
"""

from __future__ import annotations

from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
SRC = ROOT / "src" / "meshmocap"

#: (title, package or module names of meshmocap, one-line description) from the bottom up.
LAYERS = (
    ("Base", ("errors",), "every error and warning class"),
    ("Geometry", ("geometry",), "pure array functions"),
    ("Fitted models", ("models",), "the scikit-learn contract: GPLVM, classifier, shape space"),
    ("The body", ("body",), "skeleton, template, skinning, motions, rigs"),
    ("File formats", ("io",), "every format in and out"),
    ("Estimation", ("estimate",), "what a capture says before tracking"),
    ("Trackers", ("trackers",), "the methods, their options, the driver"),
    ("The studio", ("studio",), "synthetic captures with truth; hulls from silhouettes"),
    ("Analysis", ("analysis",), "metrics, evaluation, gait"),
    ("Applications", ("apps",), "reports, plots, bench, demo, exports, batch"),
    ("Python API", ("api",), "open, track, evaluate, export in a few calls"),
    ("Command line", ("cli",), "the meshmocap command"),
)


def public_modules() -> list[str]:
    """Return the dotted names of every public module and package, sorted."""
    names = []
    for path in sorted(SRC.rglob("*.py")):
        parts = path.relative_to(SRC.parent).with_suffix("").parts
        if parts[-1] == "__init__":
            parts = parts[:-1]
        if any(p.startswith("_") for p in parts[1:]):
            continue
        if path.name == "__main__.py":
            continue
        names.append(".".join(parts))
    return sorted(names)


def index_rst() -> str:
    """Return the text of ``docs/api/index.rst``."""
    modules = public_modules()
    out = [
        ".. _api:",
        "",
        "API reference",
        "=============",
        "",
        "Every public module, layer by layer from the bottom up (a module imports only its own",
        "layer and the layers below). Shapes, dtypes, units and frames are in each function's",
        "parameters: metres, seconds, radians, world frame right-handed with Z up.",
        "",
    ]
    for title, packages, blurb in LAYERS:
        mods = [
            m
            for m in modules
            if any(m == f"meshmocap.{p}" or m.startswith(f"meshmocap.{p}.") for p in packages)
        ]
        out += [title, "-" * len(title), "", blurb[0].upper() + blurb[1:] + ".", ""]
        out += [".. autosummary::", "   :toctree: generated", ""]
        out += [f"   {m}" for m in mods]
        out.append("")
    top = [m for m in modules if m == "meshmocap"]
    out += ["Package", "-------", "", ".. autosummary::", "   :toctree: generated", ""]
    out += [f"   {m}" for m in top]
    out.append("")
    return "\n".join(out)


if __name__ == "__main__":
    (ROOT / "docs" / "api" / "index.rst").write_text(index_rst())
