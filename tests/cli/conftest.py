"""Fixtures of the command tests: a saved pose manifold of neutral_5k beside a walk."""

import pytest

from meshmocap.body.template import load_template
from meshmocap.trackers.cage.manifold import fit_pose_manifold
from meshmocap.trackers.cage.oqr import build_oqr
from meshmocap.trackers.cage.training_poses import load_pose_sources


@pytest.fixture(scope="session")
def cage_setup(synth_capture, tmp_path_factory):
    """A small saved manifold of neutral_5k and a 3-frame synthetic walk capture."""
    root = tmp_path_factory.mktemp("cli_cage")
    t = load_template("neutral_5k")
    oqr = build_oqr(t)
    poses = load_pose_sources(["walk"], t, oqr=oqr, duration=1.2, fps=15.0)
    manifold = fit_pose_manifold(poses, t, oqr=oqr, n_samples=18, max_iter=200).save(
        root / "manifold.npz"
    )
    cap = synth_capture("walk", stop=6, step=2, voxel_size=0.02)
    return root, t, manifold, cap
