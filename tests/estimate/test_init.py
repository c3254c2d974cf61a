"""What a capture says before tracking: occupancy and normals from any points, the up axis
and units of mesh files, the automatic first pose, and the fit-quality checks."""

import numpy as np
import pytest

from meshmocap.body.procedural import procedural_motion
from meshmocap.body.template import load_template
from meshmocap.errors import InputError
from meshmocap.estimate.pose.first_pose import initial_pose, limb_candidates, seed_pose
from meshmocap.estimate.pose.fit import PoseFitter, pose_of_vertices
from meshmocap.estimate.recovery.observe import ObservedFrame
from meshmocap.estimate.recovery.quality import fit_quality, limb_labels
from meshmocap.estimate.recovery.reinit import Recovery
from meshmocap.geometry.mesh import vertex_normals
from meshmocap.geometry.rotations import so3_exp
from meshmocap.io.axes import detect_axes
from meshmocap.io.capture import SequenceFrame

TURN, SHIFT = 2.3, np.array([0.7, -0.4, 0.0])


@pytest.fixture(scope="module")
def body():
    """neutral_5k walking (procedural walk, frame 10 at 30 fps) with its arms in a T-pose,
    turned 2.3 rad about Z and moved: the template, the pose and the posed template."""
    t = load_template("neutral_5k")
    m = procedural_motion("walk", t, duration=1.0, fps=30.0)
    R, root = m.rotations[10].copy(), m.root_positions[10].copy()
    arms = [t.skeleton.index(n) for n in ("LeftArm", "RightArm", "LeftForeArm", "RightForeArm")]
    R[arms] = seed_pose(t, "t_pose")[arms]
    R[0] = so3_exp(np.array([0.0, 0.0, TURN])) @ R[0]
    root = so3_exp(np.array([0.0, 0.0, TURN])) @ root + SHIFT
    return t, R, root, t.pose(R, root)


def _frame(V, F=None, index=0):
    """A frame of a point cloud (``F`` None), its occupancy and normals computed once."""
    return ObservedFrame(SequenceFrame(index, (V, F), None))


def test_a_point_cloud_frame_has_outward_normals_and_a_signed_distance():
    k = np.arange(20000) + 0.5  # a sphere sampled evenly (Fibonacci lattice), 7.5 mm apart
    z, phi = 1 - 2 * k / len(k), np.pi * (1 + 5**0.5) * k
    d = np.stack([np.sqrt(1 - z**2) * np.cos(phi), np.sqrt(1 - z**2) * np.sin(phi), z], 1)
    P = 0.3 * d + [1.0, 2.0, 0.5]
    obs = _frame(P)  # a cloud without normals: estimated (geometry.normals)
    Q, N = obs.points
    radial = (Q - [1.0, 2.0, 0.5]) / 0.3
    assert np.percentile(np.sum(N * radial, axis=1), 5) > 0.9  # outward, 5th percentile
    inside = obs.field(np.array([[1.0, 2.0, 0.5], [1.0, 2.0, 1.2]]))
    assert inside[0] == pytest.approx(-0.3, abs=0.02) and inside[1] == pytest.approx(0.4, abs=0.02)


def test_up_axis_units_and_distance_are_read_or_refused(body):
    posed = body[3]
    V = posed.V
    a = detect_axes(V)
    assert (a.up, a.units) == ("z", "m") and 1.5 < a.span < 2.0  # T-pose: arm span ~ height
    assert detect_axes(V * 1000).units == "mm" and detect_axes(V * 100).units == "cm"
    yup = V @ np.array([[1.0, 0, 0], [0, 0, 1], [0, -1, 0]]).T  # (x, y, z) → (x, z, −y)
    assert detect_axes(yup).up == "y"
    with pytest.raises(InputError, match="set --units") as e:
        detect_axes(V * 10)
    assert "\n" not in str(e.value)
    with pytest.raises(InputError, match="1000 km from the origin"):
        detect_axes(V + [1e6, 0.0, 0.0])
    ball = 0.3 * np.random.default_rng(1).normal(size=(500, 3))  # a crouch seen as a ball
    with pytest.raises(InputError, match="set --up"):
        detect_axes(ball)
    assert detect_axes(V * 10, units="cm").units == "cm"  # given: not detected


@pytest.mark.slow
def test_first_pose_found_anywhere_facing_any_way(body):
    # ~10 s: the whole global search (6 seeds × 8 headings, limbs re-seeded)
    t, posed = body[0], body[3]
    V = posed.V
    res = initial_pose(t, V, vertex_normals(V, t.F), keep=2)
    err = np.linalg.norm(t.pose(res.R, res.root).eval_joints - posed.eval_joints, axis=1)
    assert err.mean() < 0.015 and err.max() < 0.04  # measured 3.6 mm mean, 9.6 max
    assert len(res.candidates) == 2 and res.score <= res.candidates[1].score + 1e-12


def test_a_lost_arm_is_found_again_by_its_limb_search(body):
    t, R, root, posed = body
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


def test_fit_quality_names_the_limb_outside_and_unexplained(body):
    t, R, root, posed = body
    labels = limb_labels(t)
    obs = _frame(posed.V, t.F)  # the true surface, closed
    P, field = obs.points[0], obs.field
    good = fit_quality(posed.V, labels, P, field)
    assert good.lost == () and max(good.outside.values()) < 0.02
    down = R.copy()
    down[t.skeleton.index("LeftArm")] = np.eye(3)
    q = fit_quality(t.pose(down, root).V, labels, P, field)
    assert q.lost == ("left_arm",)
    assert q.outside["left_arm"] > 0.25 and q.unexplained["left_arm"] > 0.02
    assert "left_arm (" in q.describe() and "outside the observations" in q.describe()


def test_a_limb_the_observations_miss_is_lost_until_seen_again(body):
    t, R, root, posed = body
    names = t.eval_skeleton.names
    arm = np.isin(t.part_labels, [names.index(n) for n in ("left_elbow", "left_wrist")])
    down = R.copy()
    down[t.skeleton.index("LeftArm")] = np.eye(3)
    hanging = t.pose(down, root).V  # where a tracker pulls an arm the observations miss
    rec = Recovery(t, R, root)
    assert rec.assess(_frame(posed.V, index=0), posed.V).lost == ()
    for i in (1, 2):  # the observations miss the forearm and hand; the tracked arm hangs
        q = rec.assess(_frame(posed.V[~arm], index=i), hanging)
        assert "left_arm" in q.lost and "not observed where it was last seen" in q.describe()
    held = rec.coast_pose()[t.skeleton.index("LeftArm")]
    assert np.abs(held - R[t.skeleton.index("LeftArm")]).max() < 0.05  # held as last seen
    assert rec.assess(_frame(posed.V, index=3), posed.V).lost == ()  # seen again
