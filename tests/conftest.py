"""Shared fixtures: the real third-party data in ../shared/data (skipped where absent, and
counted in one line at the end of the run: :func:`pytest_terminal_summary`), and a posed
body made in code."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
#: The data set's folder: ../shared/data beside the project (``MESHMOCAP_SHARED_DATA``
#: names another).
SHARED_DATA = Path(os.environ.get("MESHMOCAP_SHARED_DATA") or ROOT.parent / "shared" / "data")


#: Where a reader of a fresh clone learns what the data set is and where it comes from.
DATA_DOC = "docs/reference.rst, 'Test data'"


@pytest.fixture(scope="session")
def shared_data() -> Path:
    """Path to ../shared/data; skips the test when that folder is absent."""
    if not SHARED_DATA.is_dir():
        pytest.skip(f"real data not available: {SHARED_DATA} is absent")
    return SHARED_DATA


def pytest_terminal_summary(terminalreporter, exitstatus, config) -> None:
    """One line saying how many tests skipped because the third-party data set they read is
    absent, and where it comes from (each skip's own reason names the file it needed)."""
    skipped = terminalreporter.stats.get("skipped", [])
    data = [r for r in skipped if str(SHARED_DATA) in _skip_reason(r)]
    if data:
        terminalreporter.write_line(
            f"meshmocap: {len(data)} tests skipped: they read real third-party data (CMU "
            f"motion capture, the MIT crane sequence) from {SHARED_DATA}, which is absent "
            f"here and not shipped with the project (licences); see {DATA_DOC}",
            yellow=True,
        )


def _skip_reason(report) -> str:
    """The reason of a skipped test's report (``(file, line, reason)``), or ''."""
    longrepr = getattr(report, "longrepr", None)
    return str(longrepr[2]) if isinstance(longrepr, tuple) and len(longrepr) == 3 else ""


@pytest.fixture(scope="session")
def cmu(shared_data: Path) -> Path:
    """Path to the CMU motion-capture clips in ../shared/data/mocap/cmu."""
    path = shared_data / "mocap" / "cmu"
    if not path.is_dir():
        pytest.skip(f"CMU clips not available: {path} is absent")
    return path


@pytest.fixture(autouse=True, scope="session")
def _manifold_cache(tmp_path_factory):
    """Default pose manifolds learned by tests are cached in a session folder, not in the
    user's cache (``MESHMOCAP_CACHE``)."""
    mp = pytest.MonkeyPatch()
    mp.setenv("MESHMOCAP_CACHE", str(tmp_path_factory.mktemp("manifold_cache")))
    yield
    mp.undo()


@pytest.fixture(scope="session")
def walker():
    """neutral_5k walking (procedural walk, frame 10 at 30 fps) with its arms in a T-pose,
    turned 2.3 rad about Z and moved by (0.7, −0.4, 0) m: ``(template, R (J, 3, 3), root
    (3,), the posed template)``."""
    from meshmocap.body.procedural import procedural_motion
    from meshmocap.body.template import load_template
    from meshmocap.estimate.pose.library import seed_pose
    from meshmocap.geometry.rotations import so3_exp

    turn, shift = 2.3, np.array([0.7, -0.4, 0.0])
    t = load_template("neutral_5k")
    m = procedural_motion("walk", t, duration=1.0, fps=30.0)
    R, root = m.rotations[10].copy(), m.root_positions[10].copy()
    arms = [t.skeleton.index(n) for n in ("LeftArm", "RightArm", "LeftForeArm", "RightForeArm")]
    R[arms] = seed_pose(t, "t_pose")[arms]
    R[0] = so3_exp(np.array([0.0, 0.0, turn])) @ R[0]
    root = so3_exp(np.array([0.0, 0.0, turn])) @ root + shift
    return t, R, root, t.pose(R, root)
