"""The compiled articulated-ICP pieces equal their numpy references: the posed model, the
moment-assembled normal equations (against the dense ``Σ JᵀJ``), the point motion, the
rotation error, the nearest compatible partner, the sampled vertex normals and the closest
points' energy as moments."""

import numpy as np
import pytest
from pykdtree.kdtree import KDTree

from meshmocap.body.articulated import (
    articulated_model,
    closest_point_system,
    model_subset,
    nearest_compatible,
    pose_points,
    residual_jacobian,
)
from meshmocap.body.articulated_system import (
    closest_point_moments,
    moment_plan,
    normal_equations,
    pair_moments,
    point_motion,
    posed_model,
    rotation_error,
)
from meshmocap.body.skeleton import forward_kinematics
from meshmocap.body.template import load_template
from meshmocap.geometry.mesh import vertex_normals, vertex_normals_at
from meshmocap.geometry.rotations import cross, so3_exp, so3_log


@pytest.fixture(scope="module")
def setup():
    """neutral_5k, a 300-point model and a random pose far from rest (float64)."""
    template = load_template("neutral_5k")
    rng = np.random.default_rng(7)
    J = template.skeleton.n_joints
    R = so3_exp(rng.normal(scale=0.4, size=(J, 3)))
    model = articulated_model(template, n_points=300, seed=2)
    return template, model, moment_plan(model), R, np.array([0.2, 0.1, 0.95])


def test_posed_model_equals_pose_points(setup):
    template, model, plan, R, root = setup
    posed = posed_model(plan, R, root)
    v, n, _ = pose_points(model, R, root)
    G, P = forward_kinematics(template.skeleton, R, root)
    assert np.abs(posed.v - v).max() < 1e-13 and np.abs(posed.n - n).max() < 1e-13
    assert np.abs(posed.G - G).max() < 1e-14 and np.abs(posed.P - P).max() < 1e-14
    # q sums to v over each point's weights
    sums = np.stack([np.bincount(model.rows, posed.q[:, c], minlength=len(v)) for c in range(3)], 1)
    assert np.abs(sums - v).max() < 1e-13


@pytest.mark.parametrize("residual", ["point_to_plane", "point_to_point"])
def test_normal_equations_equal_the_dense_jacobian_products(setup, residual):
    """H = Σ s JᵀJ and g = Σ s Jᵀr from per-point moments, against the dense rows of
    residual_jacobian: equal to 1e-12 relative (rounding only)."""
    _, model, plan, R, root = setup
    rng = np.random.default_rng(11)
    p = 900  # several pairs per model point, some points without any
    posed = posed_model(plan, R, root)
    v, _, a = pose_points(model, R, root)
    i = rng.integers(0, len(v) - 20, p)
    y = v[i] + rng.normal(scale=0.02, size=(p, 3))
    ny = rng.normal(size=(p, 3))
    ny /= np.linalg.norm(ny, axis=1, keepdims=True)
    s = rng.uniform(0.1, 2.0, p)
    S, b, r2 = pair_moments(v, i, y, ny, s, residual)
    H, g = normal_equations(plan, posed, S, b)
    r, Jr = residual_jacobian(v, a, i, y, ny, residual)
    rows = len(r) // p  # 1 (plane) or 3 (point) rows per pair, pair-major
    sw = np.repeat(s, rows)
    H_ref, g_ref = Jr.T @ (sw[:, None] * Jr), Jr.T @ (sw * r)
    assert np.abs(H - H_ref).max() < 1e-12 * np.abs(H_ref).max()
    assert np.abs(g - g_ref).max() < 1e-12 * np.abs(g_ref).max()
    assert np.allclose(r2, (r * r).reshape(p, rows).sum(axis=1), rtol=1e-12, atol=0)


def test_point_motion_equals_the_lever_arm_sum(setup):
    _, model, plan, R, root = setup
    J = R.shape[0]
    delta = np.random.default_rng(4).normal(scale=0.01, size=3 + 3 * J)
    _, _, a = pose_points(model, R, root)
    ref = delta[:3] + cross(delta[3:].reshape(1, -1, 3), a).sum(axis=1)
    got = point_motion(plan, posed_model(plan, R, root), delta)
    assert np.abs(got - ref).max() < 1e-15 + 1e-12 * np.abs(ref).max()


@pytest.mark.parametrize("angle", [0.0, 1e-9, 0.3, np.pi - 1e-7])
def test_rotation_error_equals_so3_log(setup, angle):
    """Through the quaternion branch: near 0, generic and near π (to 1e-9 rad)."""
    template, _, plan, R, root = setup
    sk = template.skeleton
    rng = np.random.default_rng(9)
    axes = rng.normal(size=(R.shape[0], 3))
    axes /= np.linalg.norm(axes, axis=1, keepdims=True)
    R_ref = so3_exp(-angle * axes) @ R  # R R_refᵀ = exp(angle · axis)
    posed = posed_model(plan, R, root)
    G, _ = forward_kinematics(sk, R, root)
    Gp = np.concatenate([np.eye(3)[None], G[sk.parents[1:]]])
    local = so3_log(R @ np.swapaxes(R_ref, 1, 2))
    got = rotation_error(plan, posed, R, R_ref)
    if angle < np.pi - 1e-3:  # the log is unique: compare with so3_log
        assert np.abs(got - np.einsum("jab,jb->ja", Gp, local)).max() < 1e-9
    # at π ± the sign is ambiguous; the world-frame vector has the right length and axis
    world = np.einsum("jab,jb->ja", Gp, angle * axes)
    assert np.abs(np.abs(np.sum(got * world, axis=1)) - angle * angle).max() < 1e-6


def test_nearest_compatible_is_the_first_compatible_of_k(setup):
    """The two-stage search (nearest first, k only for the rejected) gives the one-stage
    answer: the nearest of the k nearest within max_distance with compatible normals."""
    rng = np.random.default_rng(3)
    Y = rng.uniform(-1, 1, size=(3000, 3))
    NY = rng.normal(size=(3000, 3))
    NY /= np.linalg.norm(NY, axis=1, keepdims=True)
    q = rng.uniform(-1.1, 1.1, size=(800, 3))
    nq = rng.normal(size=(800, 3))
    nq /= np.linalg.norm(nq, axis=1, keepdims=True)
    tree = KDTree(Y)
    for k in (1, 8):
        qi, partner = nearest_compatible(tree, NY, q, nq, k=k, max_distance=0.15, normal_cos=0.3)
        _, idx = tree.query(q, k=k, distance_upper_bound=0.15)
        idx = idx.reshape(len(q), k).astype(np.int64)
        found = idx < tree.n
        safe = np.where(found, idx, 0)
        ok = found & (np.einsum("qkc,qc->qk", NY[safe], nq) > 0.3)
        has = ok.any(axis=1)
        assert np.array_equal(qi, np.flatnonzero(has))
        assert np.array_equal(partner, safe[has, np.argmax(ok[has], axis=1)])
        assert 0.1 * len(q) < len(qi) < len(q)  # some rejected, some found


def test_vertex_normals_are_the_area_weighted_face_normals(setup):
    """The compiled sums are NumPy's area-weighted face normals added to their corners, to
    rounding, for the template and for a random soup with an unused vertex."""
    from meshmocap.geometry.mesh import face_normals

    rng = np.random.default_rng(2)
    V0, F0 = setup[0].V, setup[0].F
    for V, F in ((V0, F0), (rng.normal(size=(50, 3)), rng.integers(0, 49, size=(80, 3)))):
        N = face_normals(V, F, normalize=False)
        S = np.zeros((len(V), 3))
        for c in range(3):
            np.add.at(S, F[:, c], N)
        n = np.linalg.norm(S, axis=1, keepdims=True)
        want = np.divide(S, n, out=np.zeros_like(S), where=n > 0)
        assert np.abs(vertex_normals(V, F) - want).max() < 1e-12
    assert np.array_equal(vertex_normals(V, F)[-1], np.zeros(3))  # vertex 49: no face


def test_vertex_normals_at_equals_every_normal_picked(setup):
    template = setup[0]
    V, F = template.V, template.F
    idx = np.random.default_rng(1).choice(len(V), 700)  # with repeats
    assert np.array_equal(vertex_normals_at(V, F, idx), vertex_normals(V, F)[idx])


def test_closest_point_moments_give_closest_point_systems_equations(setup):
    """Both directions' pairs as per-point moments, then normal_equations: the dense
    closest_point_system (point-to-plane plus a tenth of a subsample's point-to-point) to
    1e-12 relative; and a model restricted to some points poses them as the whole does."""
    _, model, plan, R, root = setup
    rng = np.random.default_rng(3)
    posed = posed_model(plan, R, root)
    v, _, a = pose_points(model, R, root)
    Y = v[rng.integers(0, len(v), 1200)] + rng.normal(scale=0.02, size=(1200, 3))
    NY = rng.normal(size=(1200, 3))
    NY /= np.linalg.norm(NY, axis=1, keepdims=True)
    pairs = [
        (rng.integers(0, len(v), 700), rng.integers(0, 1200, 700)),
        (rng.integers(0, len(v), 1100), rng.integers(0, 1200, 1100)),
    ]
    H_ref, g_ref = closest_point_system(v, a, pairs, (1.0, 0.5), Y, NY)
    S, b = closest_point_moments(posed.v, pairs, (1.0, 0.5), Y, NY)
    H, g = normal_equations(plan, posed, S, b)
    assert np.abs(H - H_ref).max() < 1e-12 * np.abs(H_ref).max()
    assert np.abs(g - g_ref).max() < 1e-12 * np.abs(g_ref).max()
    keep = np.sort(rng.choice(len(v), 40, replace=False))
    vs, ns, as_ = pose_points(model_subset(model, keep), R, root)
    _, n, _ = pose_points(model, R, root)
    assert np.array_equal(vs, v[keep]) and np.array_equal(ns, n[keep])
    assert np.array_equal(as_, a[keep])
