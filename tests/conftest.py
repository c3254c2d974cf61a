"""Shared fixtures: the real third-party data in ../shared/data (skipped where absent), and
a posed body made in code."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
SHARED_DATA = ROOT.parent / "shared" / "data"


@pytest.fixture(scope="session")
def shared_data() -> Path:
    """Path to ../shared/data; skips the test when that folder is absent."""
    if not SHARED_DATA.is_dir():
        pytest.skip(f"real data not available: {SHARED_DATA} is absent")
    return SHARED_DATA


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
