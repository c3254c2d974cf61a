"""The surface-to-joint regressor of a template (meshmocap.body.joint_regressor)."""

import numpy as np
import pytest

from meshmocap.body.joint_regressor import joint_regressor, training_poses
from meshmocap.body.template import load_template
from meshmocap.errors import InputError
from meshmocap.geometry.rotations import so3_exp


@pytest.fixture(scope="module")
def fitted():
    t = load_template("neutral_5k")
    return t, joint_regressor(t)


def test_regressor_reads_the_joints_off_unseen_skinned_poses(fitted):
    """On poses it was not fitted on (other frames of the procedural motions, other random
    rotations) the read-out of the template's own skinning is within 3 mm on average
    (measured 1.7 mm; the ridge trades a millimetre here for robustness to surface noise)
    and every row is an affine combination (sums to 1)."""
    t, A = fitted
    V, X = training_poses(t, step=7, noise=0.2, seed=1)
    err = np.linalg.norm(np.einsum("kn,tnd->tkd", A.toarray(), V) - X, axis=2)
    assert err.mean() < 3e-3
    assert np.allclose(np.asarray(A.sum(axis=1)).ravel(), 1.0, atol=1e-12)


def test_read_out_moves_rigidly_with_the_surface(fitted):
    """Weights summing to 1 make the read-out commute with any rigid motion (to rounding)."""
    t, A = fitted
    R = so3_exp(np.array([0.3, -1.2, 2.0]))
    shift = np.array([1.5, -0.4, 0.2])
    moved = A @ (t.V @ R.T + shift)
    assert np.allclose(moved, (A @ t.V) @ R.T + shift, atol=1e-12)


def test_bad_options_are_rejected():
    t = load_template("neutral_5k")
    with pytest.raises(InputError, match="radius must be a positive float"):
        joint_regressor(t, radius=0.0)
    with pytest.raises(InputError, match="ridge must be a float ≥ 0, found -1"):
        joint_regressor(t, ridge=-1)
