"""Shared fixtures: the real third-party data in ../shared/data (skipped where absent)."""

from __future__ import annotations

from pathlib import Path

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
