"""The lost-limb search: a limb re-aimed over the sphere and fitted alone comes back where
the observations show it; the pose of tracked vertices is found from a start off; a limb
of another track grafted onto a frame."""

import numpy as np

from meshmocap.estimate.pose.fit import PoseFitter, pose_of_vertices
from meshmocap.estimate.recovery.limbs import graft_limbs, limb_candidates
from meshmocap.geometry.mesh import vertex_normals
from meshmocap.geometry.rotations import so3_exp


def test_a_lost_arm_is_found_again_by_its_limb_search(walker):
    t, R, root, posed = walker
    V = posed.V
    fitter = PoseFitter(t, V, vertex_normals(V, t.F), n_model_points=500)
    wrong = R.copy()
    wrong[t.skeleton.index("LeftArm")] = np.eye(3)  # the arm hanging instead of raised
    before = fitter.score(wrong, root)
    best = limb_candidates(fitter, wrong, root, "left_arm")[0]
    ev = t.eval_skeleton.names.index("left_wrist")
    err = np.linalg.norm(t.pose(best.R, best.root).eval_joints[ev] - posed.eval_joints[ev])
    assert best.score < before and err < 0.03  # measured 5 mm
    # the pose of tracked vertices: the truth's, from a start 0.3 rad off
    R0 = R.copy()
    R0[0] = so3_exp(np.array([0.0, 0.0, 0.3])) @ R0[0]
    Rf, rootf = pose_of_vertices(t, V, R0, root + 0.05)
    assert np.abs(t.pose(Rf, rootf).V - V).max() < 0.002


def test_pose_of_vertices_with_a_kept_model_and_a_tolerance(walker):
    from meshmocap.body.articulated import articulated_model

    t, R, root, posed = walker
    R0 = R.copy()
    R0[0] = so3_exp(np.array([0.0, 0.0, 0.05])) @ R0[0]  # a frame's motion off
    a = pose_of_vertices(t, posed.V, R0, root + 0.01)
    model = articulated_model(t, n_points=600, seed=0)
    b = pose_of_vertices(t, posed.V, R0, root + 0.01, model=model)
    assert all(np.array_equal(x, y) for x, y in zip(a, b, strict=True))  # the same model
    # stopped early, a tolerance of 2 mrad leaves the vertices within 1 mm of the fit's end
    c = pose_of_vertices(t, posed.V, R0, root + 0.01, model=model, tol=2e-3, iterations=3)
    assert np.abs(t.pose(*c).V - t.pose(*a).V).max() < 0.001
    assert np.abs(t.pose(*c).V - posed.V).max() < 0.003


def test_a_grafted_arm_turns_as_its_track_turns_it_on_the_frames_trunk(walker):
    t, R, root, posed = walker
    rng = np.random.default_rng(4)
    # track 0: the walker with a non-rigid offset per vertex; track 1: its left arm raised
    # 1 rad more and its whole body 5 cm off; track 2: another offset, the right leg bent
    V0 = posed.V + 0.002 * rng.standard_normal(posed.V.shape)
    R1, R2 = R.copy(), R.copy()
    R1[t.skeleton.index("LeftArm")] = (
        so3_exp(np.array([1.0, 0.0, 0.0])) @ R[t.skeleton.index("LeftArm")]
    )
    R2[t.skeleton.index("RightLeg")] = (
        so3_exp(np.array([0.0, 0.8, 0.0])) @ R[t.skeleton.index("RightLeg")]
    )
    shift = np.array([0.05, 0.0, 0.0])
    p1, p2 = t.pose(R1, root + shift), t.pose(R2, root)
    Rs, roots = np.stack([R, R1, R2]), np.stack([root, root + shift, root])
    Vs = np.stack([V0, p1.V, p2.V + 0.001])
    Es = np.stack([posed.eval_joints, p1.eval_joints, p2.eval_joints])
    # nothing grafted: track 0 as it is, its offsets kept
    Rg, Vg, Eg = graft_limbs(t, Rs, roots, Vs, Es, {})
    assert np.array_equal(Rg, R) and np.abs(Vg - V0).max() < 1e-12
    assert np.abs(Eg - posed.eval_joints).max() < 1e-12
    Rg, Vg, Eg = graft_limbs(t, Rs, roots, Vs, Es, {"left_arm": 1, "right_leg": 2})
    names = list(t.eval_skeleton.names)
    arm = [names.index(n) for n in ("left_shoulder", "left_elbow", "left_wrist")]
    leg = [names.index(n) for n in ("right_knee", "right_ankle")]
    rest = [k for k in range(len(names)) if k not in arm + leg]
    # the arm as track 1 turns it, hung at track 0's shoulder: track 1's less its shift
    assert np.abs(Eg[arm] - (p1.eval_joints[arm] - shift)).max() < 1e-9
    # the leg as track 2 has it (its surface 1 mm off: the offset comes with it)
    assert np.abs(Eg[leg] - p2.eval_joints[leg]).max() < 1e-9
    assert np.abs(Eg[rest] - posed.eval_joints[rest]).max() < 1e-9
    foot = t.weights[:, t.skeleton.index("RightFoot")].toarray().ravel() > 0.99
    assert np.abs(Vg[foot] - (p2.V[foot] + 0.001)).max() < 1e-9
