"""Rotation utilities: exactness claims at float64 precision."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from meshmocap.geometry.rotations import (
    euler_matrix,
    matrix_to_euler,
    rotation_between,
    slerp_matrices,
    so3_exp,
    so3_log,
)

RNG = np.random.default_rng(7)


def test_exp_log_round_trip():
    w = RNG.normal(size=(50, 3))
    w *= np.pi * 0.99 / np.linalg.norm(w, axis=1).max()  # stay below π, where log is unique
    R = so3_exp(w)
    # orthonormal with det 1 to float64 rounding
    assert np.abs(R @ np.swapaxes(R, 1, 2) - np.eye(3)).max() < 1e-12
    assert np.allclose(so3_log(R), w, atol=1e-10)
    assert np.allclose(R, Rotation.from_rotvec(w).as_matrix(), atol=1e-12)


def test_exp_tiny_angles_match_taylor():
    w = np.array([[1e-9, -2e-9, 3e-9], [0.0, 0.0, 0.0]])
    R = so3_exp(w)
    assert np.allclose(R, Rotation.from_rotvec(w).as_matrix(), atol=1e-15)


@pytest.mark.parametrize("order", ["ZXY", "ZYX", "XYZ", "YXZ"])
def test_euler_is_intrinsic_like_scipy(order):
    a = RNG.uniform(-170, 170, size=(20, 3))
    R = euler_matrix(a, order, degrees=True)
    assert np.allclose(R, Rotation.from_euler(order, a, degrees=True).as_matrix(), atol=1e-12)
    # BVH convention: the first named channel is the outermost factor
    Rz = euler_matrix(a[:, :1], order[0], degrees=True)
    rest = euler_matrix(a[:, 1:], order[1:], degrees=True)
    assert np.allclose(R, Rz @ rest, atol=1e-12)
    assert np.allclose(euler_matrix(matrix_to_euler(R, order), order), R, atol=1e-10)


def test_rotation_between_including_antiparallel():
    a = RNG.normal(size=(30, 3))
    b = RNG.normal(size=(30, 3))
    b[0] = -a[0]
    b[1] = a[1] * 3
    R = rotation_between(a, b)
    out = np.einsum("nij,nj->ni", R, a / np.linalg.norm(a, axis=1, keepdims=True))
    assert np.allclose(out, b / np.linalg.norm(b, axis=1, keepdims=True), atol=1e-10)
    assert np.allclose(R[1], np.eye(3), atol=1e-12)


def test_slerp_hits_samples_and_midpoints():
    R = so3_exp(RNG.normal(size=(6, 4, 3)) * 0.5)
    t = np.arange(6) / 10.0
    assert np.allclose(slerp_matrices(R, t, t), R, atol=1e-12)
    mid = slerp_matrices(R, t, t[:-1] + 0.05)
    # the midpoint rotation is half way along the relative rotation
    rel = so3_log(np.swapaxes(R[:-1], -1, -2) @ R[1:])
    expect = R[:-1] @ so3_exp(rel / 2)
    assert np.allclose(mid, expect, atol=1e-10)
