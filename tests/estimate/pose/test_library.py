"""The candidate poses of a search (meshmocap.estimate.pose.library)."""

import numpy as np

from meshmocap.body.template import load_template
from meshmocap.estimate.pose.library import SEEDS, hand_joints, library_poses


def test_library_candidates_keep_the_hands_at_rest():
    """The pose library's hands are other performers' and a hull hardly sees them: every
    library candidate has its hands and fingers at rest, its other joints as retargeted."""
    t = load_template("neutral_5k")
    hands = hand_joints(t)
    names = {t.skeleton.names[j] for j in hands}
    assert {"LeftHand", "RightHand", "LeftFingerBase", "RThumb"} <= names
    assert not names & {"LeftForeArm", "RightForeArm", "Head"}
    poses = library_poses(t, n=50, seeds=())
    assert len(poses.R) == len(poses.labels) == 50
    assert np.allclose(poses.R[:, hands], np.eye(3))
    others = np.setdiff1d(np.arange(t.skeleton.n_joints), hands)
    assert not np.allclose(poses.R[:, others], np.eye(3), atol=1e-3)


def test_seeds_come_first_and_excluded_trials_are_left_out():
    t = load_template("neutral_5k")
    every = library_poses(t, n=50)
    assert every.labels[: len(SEEDS)] == tuple(SEEDS)
    trial = every.labels[len(SEEDS)].split(":")[0]
    without = library_poses(t, n=50, exclude_trials=(trial,))
    assert not any(lab.startswith(f"{trial}:") for lab in without.labels)
    assert len(without.labels) < len(every.labels)
