"""Tests that need a program this project does not depend on (Blender's ``bpy``,
``opensim``, ``rerun``): they skip where it is absent, unless the environment variable
``MESHMOCAP_REQUIRE`` names it (``blender,opensim``; CI sets it), where they fail."""

from __future__ import annotations

import importlib.util
import os
import re
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
#: The scripts that documentation pages show whole and tests run.
SCRIPTS = ROOT / "tests" / "apps" / "scripts"

#: How each optional program installs.
INSTALL = {
    "blender": 'pip install -e ".[blender]" (bpy; Python 3.11, NumPy < 2)',
    "opensim": 'pip install -e ".[opensim]"',
    "rerun": 'pip install -e ".[view]"',
}


def require_module(module: str, name: str) -> None:
    """Return if ``module`` (the program ``name``'s Python module) can be imported (it is
    not imported: the tests run it in a process of its own); else skip the test, or fail
    it where ``MESHMOCAP_REQUIRE`` names ``name``."""
    if importlib.util.find_spec(module) is not None:
        return
    why = f"{name} is not installed (no module {module!r}): {INSTALL[name]}"
    if name in os.environ.get("MESHMOCAP_REQUIRE", "").replace(" ", "").split(","):
        pytest.fail(f"MESHMOCAP_REQUIRE names {name}, but {why}")
    pytest.skip(why)


def included_script(page: str) -> Path:
    """The one file that the documentation page ``page`` (``guide/blender.rst``) shows whole
    (``literalinclude`` with no option that selects lines), the page having no other Python
    block."""
    page = ROOT / "docs" / page
    text = page.read_text()
    found = re.findall(r"^\.\. literalinclude:: (\S+)\n((?:   :.*\n)*)", text, flags=re.M)
    assert len(found) == 1, f"{page.name}: expected one literalinclude, found {len(found)}"
    path, options = found[0]
    assert not re.search(r":(lines|pyobject|start-after|end-before|start-at|end-at):", options)
    assert ".. code-block:: python" not in text and "\n>>> " not in text
    return (page.parent / path).resolve()


def walk_track(out: Path, n_frames: int, fps: float, *, first: int = 0, noise: float = 0.0):
    """Write a track folder ``out`` of a procedural walk on neutral_5k: ``n_frames`` frames
    at ``fps`` from capture frame ``first``, the posed template's vertices and evaluation
    joints (plus Gaussian noise of ``noise`` metres on the joints, seeded); its
    ``track.json`` states the rate. Returns the posed template."""
    from meshmocap.body.procedural import procedural_motion
    from meshmocap.body.template import load_template
    from meshmocap.io.results import FrameResult, start_track, write_frame

    template = load_template("neutral_5k")
    m = procedural_motion("walk", template, duration=n_frames / fps, fps=fps)
    posed = template.pose(m.rotations[:n_frames], m.root_positions[:n_frames])
    ev = template.eval_skeleton
    meta = {
        "method": "synthetic",
        "template": "neutral_5k",
        "fps": fps,
        "eval_names": list(ev.names),
        "eval_parents": ev.parents.tolist(),
    }
    start_track(out, meta, template.F, resume=False)
    rng = np.random.default_rng(0)
    for k in range(n_frames):
        X = posed.eval_joints[k] + rng.normal(0.0, noise, posed.eval_joints[k].shape)
        write_frame(out, FrameResult(first + k, X, posed.V[k]))
    return posed
