"""One frame tracked: a frame that cannot be fitted or read is flagged and coasted across
from the last good frame; the driver's own tests track whole sequences through it."""

import numpy as np

from meshmocap.errors import FitError
from meshmocap.io.results import FrameResult, start_track, write_frame
from meshmocap.trackers.frame_step import (
    failure_reason,
    is_finite_result,
    missing_reason,
    read_track_frame,
    track_frame,
)


class _Failing:
    """A tracker whose step fails; it remembers the state it is reset to."""

    name = "failing"
    template = None

    def step(self, frame):
        raise FitError("no convergence\nsecond line")

    def set_state(self, state):
        self.state = state


def test_a_failed_frame_repeats_the_last_good_one_flagged(tmp_path):
    start_track(tmp_path, {"method": "failing"}, np.zeros((1, 3), int), resume=False)
    good = FrameResult(3, np.ones((15, 3)), np.ones((4, 3)), state={"x": np.arange(2)})
    write_frame(tmp_path, good)
    tracker = _Failing()
    frame = type("Frame", (), {"index": 4})()
    r = track_frame(tracker, lambda: frame, 4, tmp_path, 3)
    assert r.index == 4 and not r.healthy and r.flags == ("failed",)
    assert r.message == "FitError: no convergence"
    assert np.array_equal(r.joints, good.joints) and tracker.state["x"].tolist() == [0, 1]
    # a frame that cannot be read is missing, and coasted across the same way
    r = track_frame(tracker, _absent, 5, tmp_path, 3)
    assert r.flags == ("missing",) and "absent" in r.message
    assert read_track_frame(tmp_path, 3).index == 3


def _absent():
    from meshmocap.errors import MeshmocapFileNotFoundError

    raise MeshmocapFileNotFoundError("hull 00005.ply absent")


def test_reasons_and_finiteness():
    assert failure_reason(ValueError("x" * 300)).startswith("ValueError: x")
    assert len(failure_reason(ValueError("x" * 300))) == 200
    assert missing_reason(object()) is None
    assert missing_reason(type("F", (), {"missing": "dropped"})()) == "dropped"
    bad = FrameResult(0, np.full((15, 3), np.nan), np.zeros((4, 3)))
    assert not is_finite_result(bad)


def test_the_hold_fits_the_frame_before_s_refined_surface_put_back_at_rest():
    """The body the hold fits (held_rest) is the refined surface of the frame next to this
    one, in the pose the holder held that frame in, put back at rest (its offset from the
    template's rest surface kept at the holder's share: SkeletonHold.rest_of, here without
    the parts' translations taken out); none where the refiner's last frame is not next to
    this one or not the holder's."""
    from meshmocap.body.template import load_template
    from meshmocap.estimate.pose.hold import SkeletonHold
    from meshmocap.geometry.refine import ArapRefiner
    from meshmocap.trackers.frame_step import held_rest

    t = load_template("neutral_5k")
    holder = SkeletonHold(t, n_model_points=100, iterations=1, rigid_reach=None)
    refiner = ArapRefiner(t.V, t.F, iterations=1)
    rng = np.random.default_rng(0)
    R = np.tile(np.eye(3), (t.skeleton.n_joints, 1, 1))
    root = t.skeleton.rest_positions[0] + [0.1, 0.0, 0.0]
    X = t.pose(R, root).V + rng.normal(scale=0.002, size=t.V.shape)
    assert held_rest(holder, refiner, 5) is None  # nothing refined yet
    refiner.last_ = (4, np.zeros_like(X), X)
    holder.last, holder.key = (R, root), 4
    rest = held_rest(holder, refiner, 5)  # X at rest, its offset from the template's share
    share = holder.rest_share * (X - [0.1, 0.0, 0.0] - t.V)
    np.testing.assert_allclose(rest, t.V + share, atol=1e-12)
    assert held_rest(holder, refiner, 6) is None  # not next to frame 4
    holder.key = 3
    assert held_rest(holder, refiner, 5) is None  # held at another frame
    assert held_rest(holder, None, 5) is None
    holder.key = 4
    holder.surface = False  # not a clean 4D capture: the template's own surface
    assert held_rest(holder, refiner, 5) is None


class _Held:
    """A tracker whose surface is given (no articulated pose of its own: a patch cloud's)
    and that takes the held pose."""

    def __init__(self, template, V):
        self.template, self.V = template, V

    def hold(self, frame, R, root):
        posed = self.template.pose(R, root)
        return FrameResult(frame.index, posed.eval_joints, posed.V)


def test_a_clean_4d_hold_also_starts_from_the_last_held_pose():
    """On a clean 4D capture the hold of a surface that slid (the left thigh turned 0.6 rad
    about its bone) also starts from the last held pose, directly and through the
    template's own skin, and keeps the fit of lowest cost: there the true pose. Elsewhere
    (hull files) the fit starts from the surface's pose only, as before."""
    from meshmocap.body.procedural import procedural_motion
    from meshmocap.body.template import load_template
    from meshmocap.estimate.pose.hold import SkeletonHold
    from meshmocap.geometry.mesh import vertex_normals
    from meshmocap.geometry.rotations import so3_exp
    from meshmocap.trackers.frame_step import held

    t = load_template("neutral_5k")
    m = procedural_motion("walk", t, duration=0.3, fps=30.0)
    R, root = m.rotations[5], m.root_positions[5]
    posed = t.pose(R, root)
    sk = t.skeleton
    j = sk.index("LeftUpLeg")
    axis = sk.rest_positions[sk.children[j][0]] - sk.rest_positions[j]
    R0 = R.copy()
    R0[j] = R0[j] @ so3_exp(0.6 * axis / np.linalg.norm(axis))
    slid = t.pose(R0, root).V
    frame = type("Frame", (), {"index": 5, "points": (posed.V, vertex_normals(posed.V, t.F))})()
    r = FrameResult(5, posed.eval_joints, slid, state={"R": np.zeros((7, 3, 3))})

    def hold(surface):
        holder = SkeletonHold(t, n_model_points=800, iterations=3, surface=surface)
        holder.last = (R, root)  # the last held pose: here the true one
        return held(_Held(t, slid), holder, frame, r).vertices, holder

    V_clean, holder = hold(True)
    V_hulls, _ = hold(False)
    from_slid = holder.fit(*frame.points, slid, *holder.start(slid, R, root))
    from_last = holder.fit(*frame.points, slid, R, root)
    # through the template's own skin: here the body fitted is that skin, so the same fit
    # continued from where the first stopped
    through_skin = holder.fit(*frame.points, slid, *holder.fit(*frame.points, slid, R, root))
    cost = [holder.cost(*frame.points, *f) for f in (from_slid, from_last, through_skin)]
    assert cost[2] < cost[1] < cost[0]
    np.testing.assert_array_equal(V_clean, t.pose(*through_skin).V)  # the lowest cost kept
    np.testing.assert_array_equal(V_hulls, t.pose(*from_slid).V)  # hull files: as before
    error = [np.linalg.norm(V - posed.V, axis=1).mean() for V in (V_clean, V_hulls)]
    # measured 4.5 and 4.8 mm (from the last pose alone 2.7: a fit continued past it lowers
    # the cost by sliding along the surface, which the cost cannot see)
    assert error[0] < error[1]


def test_posed_body_skins_a_rest_surface_with_the_template_s_weights():
    """posed_body: the template's own rest surface gives the template's skin; another rest
    surface is skinned with the same weights (a rest offset moves with its vertex's blended
    transform)."""
    from meshmocap.body.procedural import procedural_motion
    from meshmocap.body.template import load_template
    from meshmocap.estimate.pose.hold import SkeletonHold
    from meshmocap.trackers.frame_step import posed_body

    t = load_template("neutral_5k")
    m = procedural_motion("walk", t, duration=0.2, fps=30.0)
    R, root = m.rotations[3], m.root_positions[3]
    np.testing.assert_allclose(posed_body(t, t.V, R, root), t.pose(R, root).V, atol=1e-12)
    rest = t.V + np.array([0.0, 0.0, 0.01])  # the whole body 1 cm up at rest
    back = SkeletonHold(t, n_model_points=100).unposed(posed_body(t, rest, R, root), R, root)
    np.testing.assert_allclose(back, rest, atol=1e-9)


class _HeldOnto(_Held):
    """A :class:`_Held` that records the body it is moved onto (``surface``)."""

    def hold(self, frame, R, root, *, surface=None):
        self.surface = surface
        return super().hold(frame, R, root)


def test_a_clean_4d_hold_places_a_patch_cloud_on_the_body_it_fitted():
    """Where the hold fits the frame before's refined surface (held_rest), a tracker
    without a pose of its own (a patch cloud) is moved onto that body skinned in the held
    pose (posed_body), with the parts' translations the fit's body leaves out (the frame
    before 5 mm above the skin: there too), not onto the template's skin; without it, onto
    the skin as before."""
    from meshmocap.body.procedural import procedural_motion
    from meshmocap.body.template import load_template
    from meshmocap.estimate.pose.hold import SkeletonHold
    from meshmocap.geometry.mesh import vertex_normals
    from meshmocap.geometry.refine import ArapRefiner
    from meshmocap.trackers.frame_step import held, held_rest, posed_body

    t = load_template("neutral_5k")
    m = procedural_motion("walk", t, duration=0.3, fps=30.0)
    R, root = m.rotations[5], m.root_positions[5]
    posed = t.pose(R, root)
    frame = type("Frame", (), {"index": 5, "points": (posed.V, vertex_normals(posed.V, t.F))})()
    r = FrameResult(5, posed.eval_joints, posed.V, state={"R": np.zeros((7, 3, 3))})
    holder = SkeletonHold(t, n_model_points=400, iterations=2)
    refiner = ArapRefiner(t.V, t.F, iterations=1)
    X = t.pose(m.rotations[4], m.root_positions[4]).V + [0.0, 0.0, 0.005]  # frame 4 refined
    refiner.last_ = (4, np.zeros_like(X), X)
    holder.last, holder.key = (m.rotations[4], m.root_positions[4]), 4
    whole = held_rest(holder, refiner, 5, rigid=False)
    fitted = held_rest(holder, refiner, 5)  # the 5 mm taken out: the template's own
    assert np.abs(whole - fitted)[:, 2].mean() > 0.003
    tracker = _HeldOnto(t, posed.V)
    held(tracker, holder, frame, r, refiner=refiner, index=5)
    np.testing.assert_allclose(tracker.surface, posed_body(t, whole, *holder.last), atol=1e-12)
    holder.key = 3  # no body from the frame before: the template's skin
    held(tracker, holder, frame, r, refiner=refiner, index=5)
    assert tracker.surface is None
