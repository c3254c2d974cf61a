"""The automatic first pose: the global search finds a body anywhere, facing any way."""

import numpy as np
import pytest

from meshmocap import _progress
from meshmocap.estimate.pose.first_pose import initial_pose
from meshmocap.geometry.mesh import vertex_normals


@pytest.mark.slow
def test_first_pose_found_anywhere_facing_any_way(walker):
    # ~10 s: the whole global search (6 seeds × 8 headings, limbs re-seeded)
    t, posed = walker[0], walker[3]
    V = posed.V
    res = initial_pose(t, V, vertex_normals(V, t.F), keep=2)
    err = np.linalg.norm(t.pose(res.R, res.root).eval_joints - posed.eval_joints, axis=1)
    assert err.mean() < 0.015 and err.max() < 0.04  # measured 3.6 mm mean, 9.6 max
    assert len(res.candidates) == 2 and res.score <= res.candidates[1].score + 1e-12


def test_the_search_says_each_stage(walker, monkeypatch, capsys):
    """Every stage of the search says what it does (all said at once with a phase
    threshold of 0): a small search, one seed at two headings, one refined."""
    monkeypatch.setattr(_progress, "PHASE_SECONDS", 0.0)
    t, posed = walker[0], walker[3]
    V = posed.V
    initial_pose(
        t,
        V,
        vertex_normals(V, t.F),
        seeds=("rest",),
        n_headings=2,
        keep=1,
        coarse_iterations=2,
        iterations=2,
        limb_directions=2,
    )
    err = capsys.readouterr().err
    for stage in ("fitting the best 2 candidates", "refining the best 1 candidates"):
        assert f"meshmocap: {stage} ...\n" in err and f"meshmocap: {stage}: done in" in err
