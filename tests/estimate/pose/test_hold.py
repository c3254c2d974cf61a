"""The skeleton held by the observed surface (:mod:`meshmocap.estimate.pose.hold`): a
tracker's surface slid along the body (a thigh turned about its own axis, the pelvis
shifted) is brought back by the fit against the observations, and bad options are refused
in one line."""

import numpy as np
import pytest

from meshmocap.body.procedural import procedural_motion
from meshmocap.body.template import load_template
from meshmocap.errors import InputError
from meshmocap.estimate.pose.hold import SkeletonHold, rigid_part_translations
from meshmocap.geometry.mesh import vertex_normals
from meshmocap.geometry.rotations import so3_exp


@pytest.fixture(scope="module")
def scene():
    """neutral_5k at frame 5 of a walk (observed: its own vertices and normals) and a
    tracker's surface slid along it: the left thigh twisted 0.25 rad about its bone, the
    right upper arm 0.2 rad, the root moved 2 cm."""
    t = load_template("neutral_5k")
    m = procedural_motion("walk", t, duration=0.5, fps=30.0)
    R, root = m.rotations[5], m.root_positions[5]
    posed = t.pose(R, root)
    R0 = R.copy()
    sk = t.skeleton
    for name, angle in [("LeftUpLeg", 0.25), ("RightArm", 0.2)]:
        j = sk.index(name)
        axis = sk.rest_positions[sk.children[j][0]] - sk.rest_positions[j]
        axis = axis / np.linalg.norm(axis)
        R0[j] = R0[j] @ so3_exp(angle * axis)
    root0 = root + np.array([0.02, 0.0, 0.0])
    return t, posed, (R, root), (R0, root0)


def _joint_error(t, R, root, posed) -> float:
    """Mean evaluation-joint distance (metres) between a pose and the observed body."""
    return float(np.linalg.norm(t.pose(R, root).eval_joints - posed.eval_joints, axis=1).mean())


@pytest.mark.slow
def test_the_hold_brings_a_slid_surface_back_onto_the_observed_body(scene):
    t, posed, _, (R0, root0) = scene
    slid = t.pose(R0, root0)
    hold = SkeletonHold(t, n_model_points=800, iterations=8)
    Rs, roots = hold.start(slid.V, R0, root0)  # the pose of the slid surface
    before = _joint_error(t, Rs, roots, posed)
    R1, root1 = hold.fit(posed.V, vertex_normals(posed.V, t.F), slid.V, Rs, roots)
    after = _joint_error(t, R1, root1, posed)
    assert before > 0.01  # measured 14 mm
    assert after < 0.5 * before  # measured 4 mm
    v_err = np.linalg.norm(t.pose(R1, root1).V - posed.V, axis=1).mean()
    assert v_err < np.linalg.norm(slid.V - posed.V, axis=1).mean()


@pytest.mark.slow
def test_the_hold_leaves_the_true_pose_where_it_is(scene):
    t, posed, (R, root), _ = scene
    hold = SkeletonHold(t, n_model_points=800)
    R1, root1 = hold.fit(posed.V, vertex_normals(posed.V, t.F), posed.V, R, root)
    assert _joint_error(t, R1, root1, posed) < 0.002


@pytest.mark.parametrize(
    "kw",
    [
        {"iterations": 0},
        {"surface_weight": -1.0},
        {"lambda_pose": float("nan")},
        {"rest_share": 1.5},
        {"rigid_reach": 0.0},
    ],
)
def test_bad_options_are_refused_in_one_line(scene, kw):
    with pytest.raises(InputError, match="SkeletonHold") as e:
        SkeletonHold(scene[0], **kw)
    assert "\n" not in str(e.value)


def test_unposed_puts_a_posed_surface_back_in_the_rest_pose(scene):
    """The template's skin in a pose, put back by the inverse of each vertex's blended
    transform, is the template's own rest surface."""
    t, posed, (R, root), _ = scene
    hold = SkeletonHold(t, n_model_points=200, iterations=1)
    np.testing.assert_allclose(hold.unposed(posed.V, R, root), t.V, atol=1e-9)


def test_the_rest_surface_keeps_its_share_of_the_offset_from_the_template(scene):
    """rest_of: a surface held at a skeleton slid 2 cm up inside it goes back to rest 2 cm
    low by unposed, and by rest_of only its share β of that; β = 1 is unposed itself."""
    t, posed, (R, root), _ = scene
    high = root + np.array([0.0, 0.0, 0.02])
    hold = SkeletonHold(t, n_model_points=200, iterations=1, rest_share=0.7, rigid_reach=None)
    U = hold.unposed(posed.V, R, high)
    assert np.linalg.norm(U - t.V, axis=1).mean() > 0.019
    np.testing.assert_allclose(hold.rest_of(posed.V, R, high) - t.V, 0.7 * (U - t.V), atol=1e-12)
    whole = SkeletonHold(t, n_model_points=200, iterations=1, rest_share=1.0, rigid_reach=None)
    np.testing.assert_allclose(whole.rest_of(posed.V, R, high), U, atol=1e-12)


def test_a_slide_the_parts_carry_as_a_whole_is_taken_out_of_the_rest_surface(scene):
    """rest_of with rigid_reach: the same surface held 2 cm too high goes back to the
    template's own rest surface (every part's skin translated as a whole: 14 mm off on
    average without rigid_reach, 0.08 mm with it; at most 2.7 mm where a vertex blends parts
    turned apart), while vertices pushed 4 cm out on their own (a loose skin hung off the
    left thigh) keep their share of their whole offset."""
    t, posed, (R, root), _ = scene
    high = root + np.array([0.0, 0.0, 0.02])
    hold = SkeletonHold(t, n_model_points=200, iterations=1, rest_share=0.7, rigid_reach=0.01)
    sk = t.skeleton
    top = np.asarray(t.weights.argmax(axis=1)).ravel()
    loose = np.flatnonzero(top == sk.index("LeftUpLeg"))[::3]
    others = np.setdiff1d(np.arange(t.n_vertices), loose)
    X = posed.V.copy()
    X[loose] += 0.04 * vertex_normals(posed.V, t.F)[loose]
    for surface in (posed.V, X):
        rest = hold.rest_of(surface, R, high)
        off = np.linalg.norm(rest[others] - t.V[others], axis=1)
        assert off.mean() < 2e-4 and off.max() < 3e-3  # the slide taken out
    U = hold.unposed(X, R, high)
    np.testing.assert_allclose(rest[loose] - t.V[loose], 0.7 * (U - t.V)[loose], atol=1e-12)
    whole = hold.rest_of(X, R, high, rigid=False)  # the translations kept: V + β D
    np.testing.assert_allclose(whole - t.V, 0.7 * (U - t.V), atol=1e-12)


def test_rigid_part_translations_are_the_parts_own_on_the_rigid_vertices():
    """Offsets that are each part's translation blended by the weights come back whole;
    a vertex far from its parts' translation is left out (zero) and does not bend theirs."""
    rng = np.random.default_rng(0)
    W = rng.random((300, 4))
    W[W < 0.6] = 0.0
    W[np.arange(300), rng.integers(0, 4, 300)] += 1.0
    W /= W.sum(axis=1, keepdims=True)
    T = rng.normal(scale=0.01, size=(4, 3))
    D = W @ T
    np.testing.assert_allclose(rigid_part_translations(D, W, reach=0.005), D, atol=1e-12)
    D[:10] += 0.05
    out = rigid_part_translations(D, W, reach=0.005)
    np.testing.assert_array_equal(out[:10], 0.0)
    np.testing.assert_allclose(out[10:], (W @ T)[10:], atol=1e-12)


def test_rigid_part_translations_refuses_bad_input_in_one_line():
    with pytest.raises(InputError, match="rigid_part_translations: D must be") as e:
        rigid_part_translations(np.zeros((5, 3)), np.ones((4, 2)), reach=0.01)
    assert "\n" not in str(e.value)
    with pytest.raises(InputError, match="reach must be > 0"):
        rigid_part_translations(np.zeros((4, 3)), np.ones((4, 2)), reach=0.0)


def test_a_rest_surface_is_the_body_fitted(scene):
    """Fitted with the template's own rest surface the pose is the same as without; with
    the rest surface grown 1 cm along its normals, observations of that body in the true
    pose hold the true pose."""
    t, posed, (R, root), _ = scene
    hold = SkeletonHold(t, n_model_points=400, iterations=3)
    N = vertex_normals(posed.V, t.F)
    a = hold.fit(posed.V, N, posed.V, R, root)
    b = hold.fit(posed.V, N, posed.V, R, root, rest=t.V)
    np.testing.assert_allclose(a[0], b[0], atol=1e-12)
    np.testing.assert_allclose(a[1], b[1], atol=1e-12)
    grown = t.V + 0.01 * vertex_normals(t.V, t.F)
    sk = t.skeleton
    from meshmocap.body.skeleton import forward_kinematics
    from meshmocap.body.skinning import skinning_transforms

    G, P = forward_kinematics(sk, R, root)
    A = skinning_transforms(G, P, sk.rest_positions)
    B = np.asarray(t.weights @ A.reshape(len(A), 12)).reshape(-1, 3, 4)
    Y = np.einsum("nab,nb->na", B[:, :, :3], grown) + B[:, :, 3]  # the grown body posed
    R1, root1 = hold.fit(Y, vertex_normals(Y, t.F), posed.V, R, root, rest=grown)
    assert _joint_error(t, R1, root1, posed) < 0.002


def test_the_cost_is_lower_at_the_observed_pose(scene):
    """The cost two fits are compared by: lower at the observed body's own pose than at the
    slid pose, never above twice the last reach squared (an observed point with no model
    point within reach counts that much: with few model points, many)."""
    t, posed, (R, root), (R0, root0) = scene
    hold = SkeletonHold(t, n_model_points=400, iterations=1)
    N = vertex_normals(posed.V, t.F)
    at_truth, slid = hold.cost(posed.V, N, R, root), hold.cost(posed.V, N, R0, root0)
    assert 0.0 <= at_truth < 0.9 * slid  # measured 3.3e-4 and 4.2e-4 m²
    assert slid <= 2 * hold.max_distance[1] ** 2
    # the rest surface it is given is the body posed, as in fit
    assert hold.cost(posed.V, N, R, root, rest=t.V) == at_truth
