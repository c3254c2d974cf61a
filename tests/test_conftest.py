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
