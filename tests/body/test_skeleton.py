"""Skeletons, forward kinematics, motions and resampling."""

import numpy as np
import pytest

from meshmocap.body.motion import Y_UP_TO_Z_UP, Motion, resample
from meshmocap.body.skeleton import Skeleton, forward_kinematics, local_rotations
from meshmocap.errors import InputError, SkeletonError
from meshmocap.geometry.rotations import axis_rotation, so3_exp
from toys import toy_skeleton

RNG = np.random.default_rng(3)


def test_rest_fk_reproduces_rest_positions():
    sk = toy_skeleton()
    J = sk.n_joints
    G, P = forward_kinematics(sk, np.tile(np.eye(3), (J, 1, 1)), sk.rest_positions[0])
    assert np.allclose(P, sk.rest_positions, atol=1e-15)
    assert np.allclose(G, np.eye(3))


def test_fk_matches_a_hand_computed_chain():
    sk = Skeleton(["a", "b", "c"], [-1, 0, 1], [[0, 0, 1], [1, 0, 0], [1, 0, 0]])
    R = np.stack([np.eye(3), axis_rotation(np.pi / 2, "Z"), np.eye(3)])
    _, P = forward_kinematics(sk, R, np.array([0, 0, 1.0]))
    # b sits at a + x; c = b + Rz(90°) x = b + y
    assert np.allclose(P, [[0, 0, 1], [1, 0, 1], [1, 1, 1]], atol=1e-15)


def test_local_rotations_inverts_fk():
    sk = toy_skeleton()
    R = so3_exp(RNG.normal(size=(5, sk.n_joints, 3)))
    G, _ = forward_kinematics(sk, R, np.zeros((5, 3)))
    assert np.allclose(local_rotations(sk, G), R, atol=1e-12)


def test_bad_skeletons_are_rejected_with_a_reason():
    with pytest.raises(SkeletonError, match="unique"):
        Skeleton(["a", "a"], [-1, 0], np.zeros((2, 3)))
    with pytest.raises(SkeletonError, match="precede"):
        Skeleton(["a", "b", "c"], [-1, 2, 0], np.zeros((3, 3)))
    with pytest.raises(SkeletonError, match="NaN"):
        Skeleton(["a"], [-1], [[np.nan, 0, 0]])
    with pytest.raises(SkeletonError, match="no joint named 'x'"):
        toy_skeleton().index("x")


def test_axis_conversion_keeps_shape_and_turns_y_up_into_z_up():
    sk = toy_skeleton()
    R = so3_exp(RNG.normal(size=(4, sk.n_joints, 3)) * 0.3)
    m = Motion(sk, R, RNG.normal(size=(4, 3)), 30)
    C = Y_UP_TO_Z_UP
    m2 = m.transformed(C, scale=0.5)
    assert np.allclose(m2.joint_positions, 0.5 * m.joint_positions @ C.T, atol=1e-12)
    assert np.allclose(C @ [0, 1, 0], [0, 0, 1]) and np.allclose(C @ [0, 0, 1], [0, -1, 0])


def test_resample_keeps_duration_and_interpolates():
    sk = toy_skeleton()
    T = 13
    angle = np.linspace(0, 1.2, T)
    R = np.tile(np.eye(3), (T, sk.n_joints, 1, 1))
    R[:, 18] = axis_rotation(angle, "Z")
    root = np.stack([np.linspace(0, 1, T), np.zeros(T), np.ones(T)], 1)
    m = Motion(sk, R, root, 120.0)
    r = resample(m, 30.0)
    assert r.n_frames == 4 and r.fps == 30.0
    assert np.allclose(r.rotations[:, 18], axis_rotation(angle[::4], "Z"), atol=1e-12)
    up = resample(m, 240.0)
    assert up.n_frames == 25
    # a constant-rate rotation is reproduced exactly half way between samples
    assert np.allclose(
        up.rotations[1::2, 18], axis_rotation((angle[:-1] + angle[1:]) / 2, "Z"), atol=1e-12
    )
    assert np.allclose(up.root_positions[1, 0], root[0, 0] / 2 + root[1, 0] / 2)
    with pytest.raises(InputError, match="fps"):
        resample(m, 0)


def test_motion_validates_shapes():
    sk = toy_skeleton()
    with pytest.raises(InputError, match="rotations must have shape"):
        Motion(sk, np.zeros((3, 2, 3, 3)), np.zeros((3, 3)), 30)
    R = np.tile(np.eye(3), (2, sk.n_joints, 1, 1))
    with pytest.raises(InputError, match="NaN"):
        Motion(sk, R, np.full((2, 3), np.nan), 30)
    m = Motion(sk, R, np.zeros((2, 3)), 30)
    with pytest.raises(InputError, match="selects no frame"):
        m.frames(slice(5, 9))
