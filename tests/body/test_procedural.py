"""Procedural motions: deterministic, on the floor, no sliding, each doing what it says."""

import numpy as np
import pytest

from meshmocap.body.contact import foot_heights
from meshmocap.body.procedural import PROCEDURAL_MOTIONS, procedural_motion, walk
from meshmocap.body.template import load_template
from meshmocap.errors import InputError


@pytest.fixture(scope="module")
def t():
    return load_template("neutral_5k")


@pytest.mark.parametrize("name", PROCEDURAL_MOTIONS)
def test_every_motion_is_deterministic_finite_and_grounded(t, name):
    a = procedural_motion(name, t, duration=2.0, fps=30.0)
    b = procedural_motion(name, t, duration=2.0, fps=30.0)
    assert a.n_frames == 61 and np.array_equal(a.rotations, b.rotations)
    assert np.isfinite(a.joint_positions).all()
    low = foot_heights(a, t).min(axis=1)
    assert low.min() > -1e-9  # never through the floor
    if name not in ("jog", "jumping_jacks"):  # no flight phase: a foot always touches
        assert np.abs(low).max() < 1e-9


def test_walk_plants_the_stance_foot_and_moves_at_walking_speed(t):
    m = walk(t, duration=4.0, fps=60.0)
    h = foot_heights(m, t)
    stance = np.argmin(h, axis=1)
    ankles = m.joint_positions[:, [m.skeleton.index("LeftFoot"), m.skeleton.index("RightFoot")], :2]
    same = stance[1:] == stance[:-1]
    step = np.linalg.norm(np.diff(ankles, axis=0)[np.arange(len(same)), stance[1:]], axis=1)
    assert step[same].max() < 1e-9  # the stance ankle does not move at all
    speed = np.linalg.norm(m.root_positions[-1, :2] - m.root_positions[0, :2]) / m.duration
    assert 0.8 < speed < 1.6  # m/s, the range of human walking
    assert m.root_positions[-1, 1] < m.root_positions[0, 1]  # forward is −Y


def test_jog_is_faster_with_flight(t):
    m = procedural_motion("jog", t, duration=3.0, fps=60.0)
    speed = np.linalg.norm(m.root_positions[-1, :2] - m.root_positions[0, :2]) / m.duration
    assert speed > 1.8
    assert foot_heights(m, t).min(axis=1).max() > 0.02  # both feet off the floor at times


def test_turn_squat_raises_and_jacks_do_what_they_say(t):
    turn = procedural_motion("turn", t, duration=2.0, fps=30.0, turn_rate=90.0)
    fwd = turn.global_rotations[:, 0] @ [0.0, -1.0, 0.0]
    heading = np.degrees(np.unwrap(np.arctan2(fwd[:, 0], -fwd[:, 1])))
    assert heading[-1] - heading[0] == pytest.approx(180.0, abs=1e-6)
    sq = procedural_motion("squat", t, duration=3.0, fps=30.0, period=3.0)
    assert sq.root_positions[0, 2] - sq.root_positions[:, 2].min() > 0.25  # pelvis drops
    up = procedural_motion("arm_raises", t, duration=3.0, fps=30.0, period=3.0)
    J = up.joint_positions
    head, wrist = up.skeleton.index("Head"), up.skeleton.index("LeftHand")
    assert (J[:, wrist, 2] > J[:, head, 2]).any()  # hands above the head at the top
    jj = procedural_motion("jumping_jacks", t, duration=2.0, fps=60.0, jump_height=0.1)
    assert foot_heights(jj, t).min(axis=1).max() == pytest.approx(0.1, abs=0.005)


def test_bad_parameters_are_rejected(t):
    with pytest.raises(InputError, match="one of"):
        procedural_motion("moonwalk", t)
    with pytest.raises(InputError, match="duration must be a positive number"):
        procedural_motion("walk", t, duration=-1.0)
    with pytest.raises(InputError, match="unexpected keyword"):
        procedural_motion("walk", t, speed=3.0)
