"""The lost-limb search: a limb re-aimed over the sphere and fitted alone comes back where
the observations show it; the pose of tracked vertices is found from a start off."""

import numpy as np

from meshmocap.estimate.pose.fit import PoseFitter, pose_of_vertices
from meshmocap.estimate.recovery.limbs import limb_candidates
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
