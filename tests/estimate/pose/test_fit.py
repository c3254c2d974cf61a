"""The articulated fit to observed points (:mod:`meshmocap.estimate.pose.fit`): the fitter
recovers a pose from a start centimetres off, moves only what it is asked to, and ranks
poses by a score that prefers the true one; the silhouette mismatch is zero on the mesh's
own silhouettes; the pose of known vertices is recovered to a fraction of a millimetre."""

import numpy as np
import pytest

from meshmocap.body.procedural import procedural_motion
from meshmocap.body.template import load_template
from meshmocap.estimate.pose.fit import PoseFitter, pose_of_vertices, silhouette_mismatch
from meshmocap.geometry.mesh import vertex_normals
from meshmocap.geometry.rotations import so3_exp
from meshmocap.geometry.silhouette import silhouette
from meshmocap.studio.rigs import camera_rig


@pytest.fixture(scope="module")
def scene():
    """neutral_5k at frame 5 of a walk (the observed surface: its own vertices and normals),
    a fitter of it (500 model points), and a start 14 cm off (a forearm, a leg and the
    spine turned 0.2–0.4 rad, the root moved 4 cm)."""
    t = load_template("neutral_5k")
    m = procedural_motion("walk", t, duration=0.5, fps=30.0)
    R, root = m.rotations[5], m.root_positions[5]
    posed = t.pose(R, root)
    fitter = PoseFitter(t, posed.V, vertex_normals(posed.V, t.F), n_model_points=500)
    R0 = R.copy()
    for name, angle in [("LeftForeArm", 0.4), ("RightLeg", -0.3), ("Spine1", 0.2)]:
        j = t.skeleton.index(name)
        R0[j] = so3_exp(np.array([angle, 0.0, 0.0])) @ R0[j]
    root0 = root + np.array([0.03, -0.02, 0.01])
    return t, posed, fitter, (R, root), (R0, root0)


def _joint_error(t, R, root, posed) -> float:
    """Largest evaluation-joint distance (metres) between the pose and the observed body."""
    return float(np.linalg.norm(t.pose(R, root).eval_joints - posed.eval_joints, axis=1).max())


def test_a_fit_from_a_start_centimetres_off_recovers_the_pose(scene):
    t, posed, fitter, (R, root), (R0, root0) = scene
    assert _joint_error(t, R0, root0, posed) > 0.1  # the start: a joint 14 cm away
    fit = fitter.fit(R0, root0, iterations=20, label="start")
    assert fit.label == "start" and fit.R.shape == R.shape and fit.root.shape == (3,)
    assert _joint_error(t, fit.R, fit.root, posed) < 0.015  # measured 7.5 mm
    # the score ranks: the start is worse than the truth, the fit as good as the truth
    # (500 model points: the truth's own score is their spacing, about 2 cm)
    assert fitter.score(R0, root0) > 2 * fitter.score(R, root)
    assert fit.score == pytest.approx(fitter.score(fit.R, fit.root))
    assert fit.score < fitter.score(R, root) + 1e-3


def test_only_the_joints_asked_for_move_and_the_root_can_stay(scene):
    t, _, fitter, _, (R0, root0) = scene
    arm = t.skeleton.index("LeftForeArm")
    fit = fitter.fit(R0, root0, iterations=8, joints=np.array([arm]), move_root=False)
    others = np.arange(t.skeleton.n_joints) != arm
    np.testing.assert_array_equal(fit.R[others], R0[others])
    np.testing.assert_array_equal(fit.root, root0)
    assert np.abs(fit.R[arm] - R0[arm]).max() > 0.05  # the forearm turned back
    assert fit.score < fitter.score(R0, root0)


def test_silhouette_mismatch_is_zero_on_the_mesh_own_silhouettes(scene):
    t, posed, *_ = scene
    cameras = camera_rig("humaneva4")
    masks = [silhouette(posed.V, t.F, c, assume_closed=True) for c in cameras]
    assert silhouette_mismatch(posed.V, t.F, cameras, masks) == 0.0
    shifted = silhouette_mismatch(posed.V + [0.05, 0.0, 0.0], t.F, cameras, masks)
    assert 0.2 < shifted < 1.0  # 5 cm sideways: measured 0.37 of the observed pixels
    assert silhouette_mismatch(posed.V, t.F, [], []) == 0.0  # no camera: nothing to disagree
    with pytest.raises(ValueError):  # one mask per camera
        silhouette_mismatch(posed.V, t.F, cameras, masks[:2])


def test_the_pose_of_known_vertices_is_recovered(scene):
    t, posed, _, _, (R0, root0) = scene
    R, root = pose_of_vertices(t, posed.V, R0, root0)
    assert np.abs(t.pose(R, root).V - posed.V).max() < 1e-3  # metres; measured 0.24 mm
    assert _joint_error(t, R, root, posed) < 1e-3
