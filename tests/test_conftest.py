"""The test suite's own report (tests/conftest.py): where the third-party data set is
absent, the skips it causes are counted in one line that says where the data comes from."""

import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_absent_data_is_said_once_with_where_it_comes_from(tmp_path):
    absent = tmp_path / "no-data"
    env = {**os.environ, "MESHMOCAP_SHARED_DATA": str(absent)}
    cmd = [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "-m", "not slow"]
    tests = ["tests/io/test_meshes.py", "tests/models/test_gplvm.py", "-k", "crane or walks"]
    res = subprocess.run([*cmd, *tests], cwd=ROOT, env=env, capture_output=True, text=True)
    assert res.returncode == 0, res.stdout[-2000:]
    assert f"real data not available: {absent} is absent" in res.stdout  # each skip's reason
    line = (
        f"meshmocap: 2 tests skipped: they read real third-party data (CMU motion capture, the "
        f"MIT crane sequence) from {absent}, which is absent here and not shipped with the "
        "project (licences); see docs/reference.rst, 'Test data'"
    )
    assert line in res.stdout, res.stdout[-2000:]


def test_first_pose_searches_are_shared_only_on_identical_plain_inputs():
    """The session memo of the first-pose search (tests/conftest.py) keys a call by the
    bytes of its arrays, its numbers and the template; an argument it cannot read as a
    plain value makes the call run as usual."""
    import hashlib

    import numpy as np

    from conftest import _fingerprint
    from meshmocap.body.template import load_template
    from meshmocap.geometry.carving import VoxelHull

    def key(*args, **kwargs):
        h = hashlib.sha256()
        ok = _fingerprint(h, args) and _fingerprint(h, sorted(kwargs.items()))
        return h.hexdigest() if ok else None

    P = np.random.default_rng(0).normal(size=(50, 3))
    t = load_template("neutral_5k")
    hull = VoxelHull(np.ones((2, 3, 4), bool), np.zeros(3), 0.02)
    same = key(t, P, P.copy(), hull=hull, n_headings=16)
    assert same is not None and same == key(t, P.copy(), P, hull=hull, n_headings=16)
    moved = P.copy()
    moved[7, 2] += 1e-12
    assert key(t, moved, P, hull=hull, n_headings=16) != same  # one coordinate differs
    assert key(t, P, P, hull=hull, n_headings=8) != same  # another option
    other = VoxelHull(np.ones((2, 3, 4), bool), np.zeros(3), 0.01)
    assert key(t, P, P, hull=other, n_headings=16) != same  # another voxel size
    assert key(t, P, P, library=object()) is None  # not a plain value: not shared
