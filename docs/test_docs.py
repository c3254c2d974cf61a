"""Checks of the documentation's own machinery (``pytest -q docs``)."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

DOCS = Path(__file__).resolve().parent
sys.path.insert(0, str(DOCS))
# docs/conftest.py by its path: "conftest" on the import path is the tests' (pyproject's
# pythonpath puts tests/ there)
_spec = importlib.util.spec_from_file_location("docs_conftest", DOCS / "conftest.py")
docs_conftest = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(docs_conftest)
check_output, sessions = docs_conftest.check_output, docs_conftest.sessions

from api_modules import index_rst, public_modules  # noqa: E402

# docs/conftest.py by its path: ``conftest`` on sys.path is the test suite's (tests/ is on
# pytest's pythonpath for the shared helpers)
_spec = importlib.util.spec_from_file_location("docs_conftest", DOCS / "conftest.py")
_docs_conftest = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(_docs_conftest)
check_output = _docs_conftest.check_output
sessions = _docs_conftest.sessions


def test_api_index_lists_every_public_module():
    text = (DOCS / "api" / "index.rst").read_text()
    listed = {line.strip() for line in text.splitlines() if line.startswith("   meshmocap")}
    assert set(public_modules()) == listed, "run python docs/api_modules.py"
    assert text == index_rst()


def test_sessions_join_continuations_and_keep_expected_output():
    text = """
.. code-block:: console

   $ meshmocap synth a \\
         --frames 0:6
   wrote a: 6 frames

.. code-block:: text

   $ not run
"""
    assert sessions(text) == [[("meshmocap synth a  --frames 0:6", ["wrote a: 6 frames"], 4)]]


def test_output_compared_numbers_aside():
    out = "note\ntracked 12 frames in 3.5 s (0.29 s per frame)\nmore\n"
    assert check_output(["tracked 6 frames in 1.0 s (0.100 s per frame)"], out) is None
    assert check_output(["...", "more"], out) is None
    assert "not found" in check_output(["tracked 6 frames with cage"], out)
    assert "not found" in check_output(["more", "note"], out)  # order matters
    assert check_output(["tracked 12 frames ..."], out) is None  # the line's start
    assert "not found" in check_output(["tracked 12 frames"], out)
