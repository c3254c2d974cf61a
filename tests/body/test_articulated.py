"""The one articulated Gauss–Newton step shared by ICP, the first-pose fit, automatic rigging
and the shape fit: the closest-point system's exact gradient (finite differences, with an
extra scale column), the damped solve and its failure, the step limit, and convergence of
the step on known correspondences."""

import numpy as np
import pytest
from pykdtree.kdtree import KDTree

from meshmocap.body.articulated import (
    MAX_STEP_ANGLE,
    POINT_MIX,
    add_pose_pull,
    apply_increment,
    articulated_model,
    articulated_step,
    closest_pairs,
    closest_point_system,
    damped_solve,
    limit_step,
    pose_points,
    residual_jacobian,
    rotation_error,
)
from meshmocap.body.template import load_template
from meshmocap.errors import FitError
from meshmocap.geometry.levenberg_marquardt import DAMPING
from meshmocap.geometry.rotations import so3_exp


@pytest.fixture(scope="module")
def setup():
    """neutral_5k, a 400-point model, a pose away from rest and observed points: the model
    in another pose, shifted, with noisy normals (float64)."""
    t = load_template("neutral_5k")
    rng = np.random.default_rng(5)
    J = t.skeleton.n_joints
    R = so3_exp(rng.normal(scale=0.2, size=(J, 3)))
    root = np.array([0.1, -0.1, 0.95])
    model = articulated_model(t, n_points=400, seed=1)
    R2 = R @ so3_exp(rng.normal(scale=0.05, size=(J, 3)))
    Y, NY, _ = pose_points(model, R2, root + 0.02, jacobian=False)
    NY = NY + rng.normal(scale=0.05, size=NY.shape)
    NY /= np.linalg.norm(NY, axis=1, keepdims=True)
    return t, model, R, root, np.ascontiguousarray(Y), NY


def test_closest_point_system_gradient_matches_finite_differences(setup):
    """g = Σ Jᵀr is half the gradient of the energy the system describes, over the root
    translation, every joint's rotation increment and the log of a scale about the root;
    H is JᵀJ (symmetric, positive semi-definite)."""
    t, model, R, root, Y, NY = setup
    v, nv, a = pose_points(model, R, root)
    pairs = closest_pairs(KDTree(Y), Y, NY, v, nv, max_distance=0.1, normal_cos=0.3)
    assert min(len(i) for i, _ in pairs) > 300
    weights = (1.0, 0.7)
    H, g = closest_point_system(v, a, pairs, weights, Y, NY, extra=v - root)

    def energy(x):
        R2, root2 = apply_increment(t.skeleton, R, root, x[:-1])
        u = pose_points(model, R2, root2, jacobian=False)[0]
        w = root2 + np.exp(x[-1]) * (u - root2)
        E = 0.0
        for (i, k), wt in zip(pairs, weights, strict=True):
            d = w[i] - Y[k]
            sub = slice(None, None, max(1, len(i) // 500))
            E += wt * np.mean(np.sum(NY[k] * d, axis=1) ** 2)
            E += wt * POINT_MIX * np.mean(np.sum(d[sub] ** 2, axis=1))
        return E

    n = len(g)
    eps = 1e-6
    fd = np.array([(energy(eps * e) - energy(-eps * e)) / (2 * eps) for e in np.eye(n)])
    assert np.abs(2 * g - fd).max() < 1e-7 * max(np.abs(fd).max(), 1.0)
    assert np.allclose(H, H.T, atol=1e-14) and np.linalg.eigvalsh(H).min() > -1e-10


def test_damped_solve_is_marquardt_and_fails_with_fit_error():
    rng = np.random.default_rng(0)
    A = rng.normal(size=(6, 6))
    H, g = A @ A.T, rng.normal(size=6)
    x = damped_solve(H, g, damping=0.1)
    eps = DAMPING["articulated"].floor * np.median(np.diag(H))
    assert np.allclose((H + 0.1 * np.diag(np.diag(H)) + eps * np.eye(6)) @ x, -g, atol=1e-12)
    with pytest.raises(FitError, match="singular normal equations"):
        damped_solve(H, np.full(6, np.nan), damping=0.1)
    with pytest.raises(FitError, match="singular normal equations"):
        damped_solve(np.full((2, 2), np.inf), np.ones(2), damping=0.1)


def test_the_step_turns_no_joint_more_than_the_limit():
    delta = np.zeros(3 + 3 * 3)
    delta[:3] = 5.0  # the translation is not limited
    delta[3:6] = [0.0, 2.0, 0.0]
    delta[6:9] = [0.1, 0.0, 0.0]
    out = limit_step(delta)
    assert np.allclose(out[:3], 5.0) and np.allclose(out[3:6], [0, MAX_STEP_ANGLE, 0])
    assert np.allclose(out[6:], delta[6:])  # within the limit: unchanged


def test_articulated_step_recovers_a_pose_from_known_correspondences(setup):
    """Damped Gauss–Newton steps on point-to-point residuals with known partners, a weak
    pull to the start and only some joints free, reach the pose that made the targets:
    the free joints exactly (to 1e-6 rad), the others not at all."""
    t, model, R, root, _, _ = setup
    J = t.skeleton.n_joints
    rng = np.random.default_rng(2)
    free = np.array([0, 2, 3, 7, 8, 18, 19])  # hips, legs and the left arm
    R_true = R.copy()
    R_true[free] = R[free] @ so3_exp(rng.normal(scale=0.3, size=(len(free), 3)))
    target = pose_points(model, R_true, root + 0.05, jacobian=False)[0]
    active = np.concatenate([np.arange(3), (3 + 3 * free[:, None] + np.arange(3)).ravel()])
    i = np.arange(len(target))
    R_k, root_k = R.copy(), root.copy()
    for _ in range(30):
        v, _, a = pose_points(model, R_k, root_k)
        r, Jr = residual_jacobian(v, a, i, target, target, "point_to_point")
        H, g = Jr.T @ Jr, Jr.T @ r
        add_pose_pull(H, g, rotation_error(t.skeleton, R_k, root_k, R_k), 1e-9, start=3)
        R_k, root_k, delta = articulated_step(
            t.skeleton, R_k, root_k, H[np.ix_(active, active)], g[active], active=active
        )
        assert np.abs(np.delete(delta, active)).max() == 0.0
        assert np.linalg.norm(delta[3:].reshape(J, 3), axis=1).max() <= MAX_STEP_ANGLE + 1e-12
    assert np.abs(R_k - R_true).max() < 1e-6 and np.abs(root_k - root - 0.05).max() < 1e-7
    fixed = np.setdiff1d(np.arange(J), free)
    assert np.array_equal(R_k[fixed], R[fixed])


def test_rotation_error_is_zero_at_the_reference_and_the_rest_by_default(setup):
    t, _, R, root, _, _ = setup
    assert np.abs(rotation_error(t.skeleton, R, root, R)).max() < 1e-12
    rest = np.tile(np.eye(3), (t.skeleton.n_joints, 1, 1))
    assert np.allclose(
        rotation_error(t.skeleton, R, root), rotation_error(t.skeleton, R, root, rest)
    )
