"""Rig poses fitted to tracked surfaces (body.pose_fit): exact on skinned surfaces, the
normal equations against the explicit Jacobian and finite differences, the joint term."""

import numpy as np
import pytest

from meshmocap.body.articulated import (
    apply_increment,
    articulated_model,
    pose_points,
    residual_jacobian,
)
from meshmocap.body.pose_fit import (
    eval_joint_model,
    normal_equations,
    pose_from_surface,
    rigid_alignment,
)
from meshmocap.body.procedural import procedural_motion
from meshmocap.body.template import load_template
from meshmocap.errors import InputError
from meshmocap.geometry.rotations import so3_exp


@pytest.fixture(scope="module")
def template():
    return load_template("neutral_5k")


@pytest.fixture(scope="module")
def walk(template):
    m = procedural_motion("walk", template, duration=0.4, fps=20.0)  # 8 frames
    return m, template.pose(m.rotations, m.root_positions)


def test_recovers_skinned_surfaces_exactly(template, walk):
    m, posed = walk
    fit = pose_from_surface(template, posed.V, joints=posed.eval_joints)
    assert fit.rotations.shape == m.rotations.shape and fit.n_iter.min() >= 1
    assert fit.vertex_error.max() < 1e-8 and fit.joint_error.max() < 1e-8  # metres
    np.testing.assert_allclose(fit.root_positions, m.root_positions, atol=1e-8)
    # warm starts: later frames converge in fewer iterations than the first
    assert fit.n_iter[1:].mean() < fit.n_iter[0]


def test_normal_equations_match_the_jacobian_and_finite_differences(template, walk):
    m, posed = walk
    model = articulated_model(template, n_points=300, seed=1)
    R, root = m.rotations[3], m.root_positions[3]
    Y = posed.V[5, model.sample]
    v, _, a = pose_points(model, R, root)
    cost, H, g = normal_equations(v, a, Y)
    r, Jr = residual_jacobian(v, a, np.arange(len(Y)), Y, Y, "point_to_point")
    np.testing.assert_allclose(H, Jr.T @ Jr, rtol=1e-12, atol=1e-10)
    np.testing.assert_allclose(g, Jr.T @ r, rtol=1e-12, atol=1e-12)
    assert cost == pytest.approx(float(r @ r), rel=1e-12)
    rng = np.random.default_rng(0)
    for _ in range(3):  # d cost / d delta = 2 g (float64 central differences)
        d = rng.normal(size=g.shape)
        h = 1e-6
        costs = []
        for s in (h, -h):
            R2, root2 = apply_increment(template.skeleton, R, root, s * d)
            costs.append(float(np.sum((pose_points(model, R2, root2, jacobian=False)[0] - Y) ** 2)))
        assert (costs[0] - costs[1]) / (2 * h) == pytest.approx(2 * g @ d, rel=1e-5)


def test_eval_joint_model_skins_the_evaluation_joints(template, walk):
    m, posed = walk
    v, _, _ = pose_points(eval_joint_model(template), m.rotations[2], m.root_positions[2])
    np.testing.assert_allclose(v, posed.eval_joints[2], atol=1e-12)


def test_rigid_alignment_recovers_a_rigid_motion():
    rng = np.random.default_rng(3)
    X = rng.normal(size=(50, 3))
    R = so3_exp(np.array([0.3, -1.2, 2.0]))
    Rf, t = rigid_alignment(X, X @ R.T + [1.0, 2.0, 3.0])
    np.testing.assert_allclose(Rf, R, atol=1e-12)
    np.testing.assert_allclose(t, [1.0, 2.0, 3.0], atol=1e-12)


def test_joint_term_pulls_the_fit_onto_the_given_joints(template, walk):
    _, posed = walk
    rng = np.random.default_rng(0)
    V = posed.V[:3] + rng.normal(0.0, 0.002, posed.V[:3].shape)  # 2 mm surface noise
    X = posed.eval_joints[:3] + rng.normal(0.0, 0.004, posed.eval_joints[:3].shape)
    free = pose_from_surface(template, V, joints=X, joint_weight=0.0)
    pulled = pose_from_surface(template, V, joints=X, joint_weight=5.0)
    assert pulled.joint_error.mean() < 0.7 * free.joint_error.mean()
    assert pulled.vertex_error.mean() < free.vertex_error.mean() + 0.002  # within 2 mm
    assert np.isnan(pose_from_surface(template, V[0]).joint_error).all()


def test_mistakes_are_reported(template):
    V = template.V[None]
    with pytest.raises(InputError, match=r"V must have shape \(T, 5000, 3\)"):
        pose_from_surface(template, V[:, :10])
    with pytest.raises(InputError, match="NaN"):
        pose_from_surface(template, np.full_like(V, np.nan))
    with pytest.raises(InputError, match=r"joints must be finite with shape \(1, 15, 3\)"):
        pose_from_surface(template, V, joints=np.zeros((1, 14, 3)))
    with pytest.raises(InputError, match="joint_weight"):
        pose_from_surface(template, V, joints=np.zeros((1, 15, 3)), joint_weight=-1.0)
