"""The two-way pass: lost runs found in the flags, the choice per frame made by dynamic
programming over the evidence with a switching cost, and, on a walk whose forward track
holds a run with an arm thrown off, the run replaced from a keyframe tracked backward,
recorded in ``track.json``, flagged again by the rule and resumed from its folder."""

import json
import shutil
from dataclasses import replace

import numpy as np
import pytest

from meshmocap.body.light import tracking_body
from meshmocap.body.template import load_template
from meshmocap.errors import InputError
from meshmocap.estimate.pose.first_pose import InitResult
from meshmocap.estimate.recovery.evidence import EVIDENCE, LostRule, shipped_rule
from meshmocap.estimate.recovery.quality import LIMB_PARTS
from meshmocap.estimate.recovery.reinit import Recovery
from meshmocap.io.results import read_track, write_frame
from meshmocap.trackers import two_way
from meshmocap.trackers.driver import track_sequence
from meshmocap.trackers.frame_step import read_track_frame
from meshmocap.trackers.options import TrackOptions
from meshmocap.trackers.registry import make_tracker
from meshmocap.trackers.two_way import (
    TwoWay,
    ambiguous_limbs,
    choose,
    choose_limbs,
    clearly_passes,
    evidence_cost,
    fit_margin,
    flagged_runs,
    limb_costs,
    max_keyframes,
    two_way_pass,
)


def test_flagged_runs_merge_close_runs_and_drop_short_ones():
    f = np.zeros(30, dtype=bool)
    f[[2, 3, 4, 6, 7]] = True  # one run across a gap of one frame
    f[[12]] = True  # too short
    f[[20, 21, 22, 23]] = True
    f[[29]] = True
    assert flagged_runs(f) == [(2, 7), (20, 23)]
    assert flagged_runs(f, merge_gap=0, min_run=1) == [(2, 4), (6, 7), (12, 12), (20, 23), (29, 29)]
    assert flagged_runs(np.zeros(5, dtype=bool)) == []
    assert max_keyframes(10) == 3 and max_keyframes(120) == 5


def test_the_evidence_cost_counts_lost_limbs_first_then_the_fit():
    th = np.asarray(shipped_rule().thresholds)
    ev = np.zeros((3, len(LIMB_PARTS), len(EVIDENCE)))
    k = EVIDENCE.index("outside")
    ev[1, 2, k] = 0.5 * th[k]  # a limb half-way to lost
    ev[2, 2, k] = 1.5 * th[k]  # a limb lost
    c = evidence_cost(ev)
    assert c[0] == 0.0
    assert c[1] == pytest.approx(two_way.FIT_WEIGHT * 0.5)
    assert c[2] == pytest.approx(1.0 + two_way.FIT_WEIGHT)


def test_a_frame_is_explained_where_its_fit_measures_pass_clearly_on_the_run_s_limbs():
    rule = shipped_rule()
    th = np.asarray(rule.thresholds)
    ev = np.zeros((len(LIMB_PARTS), len(EVIDENCE)))
    u, b = EVIDENCE.index("unexplained"), EVIDENCE.index("buried")
    arm, leg = list(LIMB_PARTS).index("left_arm"), list(LIMB_PARTS).index("right_leg")
    ev[arm, u] = 0.8 * th[u]  # passes the rule, barely
    ev[leg, u] = 0.2 * th[u]
    ev[leg, b] = 10.0  # buried never flags under the shipped rule: it counts 0
    assert np.isinf(th[b])
    m = fit_margin(ev, rule)
    assert m[arm] == pytest.approx(0.8) and m[leg] == pytest.approx(0.2)
    assert not rule.limb_lost(ev).any()
    assert not clearly_passes(ev, ("left_arm", "right_leg"), rule)
    assert clearly_passes(ev, ("right_leg",), rule) and clearly_passes(ev, (), rule)
    assert two_way.CLEAR == 0.5


def test_a_limb_is_ambiguous_where_a_track_the_evidence_passes_places_it_elsewhere():
    limb_of = np.array([0, 0, 4, 4, 5])  # torso, torso, left leg ×2, right leg
    rule = LostRule((np.inf,) * len(EVIDENCE), disagree=(0.15, 0.2))
    J = np.zeros((5, 3))
    others = np.zeros((4, 5, 3))
    others[0, 3, 0] = 0.16  # the forward track, not flagged: the left leg 160 mm off
    others[1, 4, 0] = 0.18  # a keyframe's track, its right leg passing: 180 mm is not enough
    others[2, 4, 0] = 0.5  # ... and lost there: 500 mm does not count
    others[3, 2, 0] = 0.9  # the forward track flagged: none of its limbs counts
    frame_lost = np.array([False, True, True, True])
    forward = np.array([True, False, False, True])
    limb_lost = np.zeros((4, len(LIMB_PARTS)), dtype=bool)
    limb_lost[2, 5] = True
    amb, d, m = ambiguous_limbs(
        J, others, frame_lost, limb_lost, limb_of, forward=forward, rule=rule
    )
    assert amb.tolist() == [False, False, False, False, True, False]
    assert d[4].tolist() == pytest.approx([0.16, 0.0, 0.0, 0.0]) and not d[5].any()
    # the measures: per limb the farthest counted forward and keyframe track
    assert m[4].tolist() == pytest.approx([0.16, 0.0]) and m[5].tolist() == pytest.approx([0, 0.18])
    others[1, 4, 0] = 0.25  # the keyframe track's passing right leg 250 mm off: ambiguous
    amb, d, _ = ambiguous_limbs(
        J, others, frame_lost, limb_lost, limb_of, forward=forward, rule=rule
    )
    assert amb[5] and d[5].tolist() == pytest.approx([0.0, 0.25, 0.0, 0.0])
    far = LostRule(rule.thresholds, disagree=(0.2, np.inf))  # keyframe tracks never count
    amb, _, m = ambiguous_limbs(
        J, others, frame_lost, limb_lost, limb_of, forward=forward, rule=far
    )
    assert not amb.any() and m[5, 1] == pytest.approx(0.25)
    amb, _, m = ambiguous_limbs(
        J, others[:0], frame_lost[:0], limb_lost[:0], limb_of, forward=forward[:0], rule=rule
    )
    assert not amb.any() and not m.any()  # no other track: nothing to disagree with


def test_the_choice_switches_where_the_tracks_agree():
    # two tracks over 10 frames: the forward lost from frame 4 on (cost 1), the other good
    # from frame 2 on (absent before); their joints agree at frame 3, 1 m apart elsewhere
    T, K = 10, 15
    cost = np.zeros((T, 2))
    cost[4:, 0] = 1.0
    cost[:2, 1] = np.inf
    J = np.zeros((T, 2, K, 3))
    J[:, 1, :, 0] = 1.0
    J[3, 1] = 0.0
    path = choose(cost, J)
    assert path.tolist() == [0, 0, 0, 1, 1, 1, 1, 1, 1, 1]
    # forced to end on the forward track: a switch back costs less than the lost frames
    path = choose(cost, J, start=0, end=0)
    assert path[0] == 0 and path[-1] == 0
    # a switch dearer than the lost frames: stay
    assert choose(cost, J, switch=100.0).tolist() == [0] * T


def test_each_limb_is_chosen_on_its_own_evidence():
    # two tracks, 8 frames, one joint per limb; the whole frame follows track 1, whose left
    # arm is lost on frames 2–5 where track 0's is not (and both tracks' arms agree at
    # frames 1 and 6); everything else ties
    T, L = 8, len(LIMB_PARTS)
    left = list(LIMB_PARTS).index("left_arm")
    cost = np.zeros((T, 2, L))
    cost[2:6, 1, left] = 1.0
    J = np.zeros((T, 2, L, 3))
    J[:, 1, left, 0] = 0.3
    J[[1, 6], 1, left] = 0.0
    path = np.ones(T, dtype=np.int64)
    out = choose_limbs(cost, J, path, np.arange(L), start=1, end=1)
    assert set(out) == {"left_arm", "right_arm", "left_leg", "right_leg"}
    assert out["left_arm"].tolist() == [1, 0, 0, 0, 0, 0, 1, 1]
    assert all(out[n].tolist() == [1] * T for n in ("right_arm", "left_leg", "right_leg"))
    # a graft dearer than the lost frames: the frame's track throughout
    dear = choose_limbs(cost, J, path, np.arange(L), graft=2.0, start=1, end=1)
    assert dear["left_arm"].tolist() == [1] * T
    # the per-limb costs sum to the whole frame's
    ev = np.random.default_rng(0).uniform(0, 0.05, (3, L, len(EVIDENCE)))
    assert np.allclose(limb_costs(ev).sum(axis=-1), evidence_cost(ev))
    # named: the points an arm turned away leaves by a leg are charged to the arm
    rule = LostRule((0.9, np.inf, 0.02, np.inf, np.inf, np.inf))
    turned = np.zeros((L, len(EVIDENCE)))
    turned[left, EVIDENCE.index("outside")] = 0.8
    turned[4, EVIDENCE.index("unexplained")] = 0.05
    raw, named = limb_costs(turned, rule), limb_costs(turned, rule, named=True)
    assert raw[4] >= 1 > raw[left] and named[left] >= 1 > named[4]


def _truth_search(capture, seen=None):
    """A keyframe search that finds each frame's true pose (the test's stand-in); the
    hints of each call appended to ``seen`` where given."""

    def search(template, frame, **hints):
        if seen is not None:
            seen.append((int(frame.index), hints))
        truth = frame.truth
        return InitResult(truth.rotations, truth.root, 0.0, "truth", ())

    return search


def _arm_off(body, frame, track_frame, recovery):
    """``track_frame`` with the left arm swung 100° off the truth, flagged by the rule."""
    t = body.light
    R = frame.truth.rotations.copy()
    k = t.skeleton.index("LeftArm")
    c, s = np.cos(1.75), np.sin(1.75)
    R[k] = R[k] @ np.array([[1, 0, 0], [0, c, -s], [0, s, c]])
    posed = t.pose(R, frame.truth.root)
    q = recovery.assess(frame, posed.V)
    state = {**track_frame.state, "evidence": q.evidence}
    joints = posed.eval_joints
    flags = ("lost",) if q.lost else ()
    return replace(track_frame, vertices=posed.V, joints=joints, flags=flags, state=state)


@pytest.fixture
def thrown(walk, tmp_path_factory):
    """The walk tracked forward by articulated ICP from the truth, then frames 3–6 replaced
    by the left arm thrown off (flagged ``lost`` by the rule): ``(folder, body)``."""
    out = tmp_path_factory.mktemp("two_way") / "track"
    t = load_template("neutral_5k")
    tracker = make_tracker("articulated_icp", max_iter=5)
    how = TrackOptions(init="truth", passes="forward", show_progress=False)
    track_sequence(tracker, t, walk, out, how)
    body = tracking_body(t)
    f0 = read_track_frame(out, 2)
    recovery = Recovery(body.light, f0.state["pose_R"], f0.state["pose_root"])
    for i in range(3, 7):
        r = _arm_off(body, walk[i], read_track_frame(out, i), recovery)
        assert "lost" in r.flags
        write_frame(out, r)
    return out, body


def _pass(walk, folder, body, monkeypatch, seen=None):
    monkeypatch.setattr(two_way, "keyframe_search", _truth_search(walk, seen))
    tracker = make_tracker("articulated_icp", max_iter=5)
    tracker.setup(body.light)
    return two_way_pass(tracker, body, walk, folder, frames=range(len(walk)), show_progress=False)


@pytest.mark.slow
def test_a_lost_run_is_replaced_from_a_keyframe_tracked_backward(
    walk, thrown, tmp_path, monkeypatch
):
    folder = tmp_path / "track"
    shutil.copytree(thrown[0], folder)
    before = read_track(folder)
    truth = np.stack([f.truth.joints for f in walk])
    seen = []
    res = _pass(walk, folder, thrown[1], monkeypatch, seen)
    after = read_track(folder)
    # the keyframe after the run, no longer flagged, is searched for the run's lost arm
    assert seen[0][0] == 7 and "left_arm" in seen[0][1]["lost"]
    err_before = 1000 * np.linalg.norm(before.joints - truth, axis=2).mean(axis=1)
    err_after = 1000 * np.linalg.norm(after.joints - truth, axis=2).mean(axis=1)
    # measured: frames 3–6 at 60–70 mm mean with the arm off, 6–9 mm after
    assert err_before[3:7].min() > 40
    assert err_after[3:7].max() < 15
    assert res.runs == ((3, 6),)
    assert res.keyframes[0]["frame"] == 7 and res.keyframes[0]["kept"]
    changed = {i for c in res.changed for i in range(c["frames"][0], c["frames"][1] + 1)}
    assert {3, 4, 5, 6} <= changed
    assert all(c["keyframe"] == 7 and c["direction"] == "backward" for c in res.changed)
    assert any("LeftArm" in c["limbs"] or "left_arm" in c["limbs"] for c in res.changed)
    # the flags recomputed by the rule on the result; the record in track.json
    assert res.flagged[0] == 4 and res.flagged[1] == 0
    assert res.ambiguous == ()  # the forward track's arm is lost there: no disagreement
    assert not any("lost" in f for f in after.flags[3:7])
    assert "two-way: from keyframe 7 (backward)" in after.messages[4]
    meta = json.loads((folder / "track.json").read_text())
    assert meta["two_way"]["complete"] and meta["two_way"]["changed"] == list(res.changed)
    # the forward pass's frames kept; a finished pass is read back, not run again
    assert (folder / "two_way" / "forward" / "frames" / "00004.npz").is_file()
    again = _pass(walk, folder, thrown[1], monkeypatch)
    assert isinstance(again, TwoWay) and again.changed == res.changed
    # killed after its search and its hypothesis's frames were written: no record, the
    # hypothesis unfinished; run again, the search is read back and the result is the same
    meta = json.loads((folder / "track.json").read_text())
    del meta["two_way"]
    (folder / "track.json").write_text(json.dumps(meta))
    (folder / "two_way" / "k00007-backward" / "done.json").unlink()
    calls = []
    monkeypatch.setattr(two_way, "keyframe_search", lambda *a, **k: calls.append(1))
    tracker = make_tracker("articulated_icp", max_iter=5)
    tracker.setup(thrown[1].light)
    res2 = two_way_pass(tracker, thrown[1], walk, folder, frames=range(8), show_progress=False)
    assert calls == []
    assert res2.changed == res.changed and res2.flagged == res.flagged
    assert np.allclose(read_track(folder).joints, after.joints, atol=1e-6)


def test_passes_is_checked():
    with pytest.raises(InputError, match="passes"):
        TrackOptions(passes="both")


def _cheap_trackers(method, t):
    """Two of ``method``'s trackers, cheap: few iterations; the cage on a small walk
    manifold (learned once)."""
    if method != "cage":
        return [make_tracker(method, template=t, max_iter=5) for _ in range(2)]
    from meshmocap.body.procedural import walk as walk_motion
    from meshmocap.trackers.cage.tracker import CageOptions, CageTracker, learn_manifold

    motions = [walk_motion(t, duration=2.0, fps=30.0, cadence=c) for c in (100.0, 120.0)]
    gp = learn_manifold(t, motions, n_components=2, n_samples=60)
    return [CageTracker(gp, CageOptions(local_iters=1, alternations=2)) for _ in range(2)]


@pytest.mark.slow
@pytest.mark.parametrize("method", ["articulated_icp", "patch", "cage"])
def test_every_tracker_steps_backward_as_accurately_as_forward(method, walk, tmp_path):
    # the walk tracked forward from its first frame's true pose and backward from its
    # last's: as accurate (the two-way pass tracks backward from its keyframes)
    t = load_template("neutral_5k")
    n = 6
    truth = np.stack([f.truth.joints for f in walk][:n])
    err = {}
    trackers = _cheap_trackers(method, t)
    for tracker, name, frames in zip(
        trackers, ("forward", "backward"), (range(n), range(n)[::-1]), strict=True
    ):
        how = TrackOptions(frames=frames, init="truth", recover=False, show_progress=False)
        track = track_sequence(tracker, t, walk, tmp_path / name, how)
        assert track.frames.tolist() == list(range(n))  # read back in frame order
        err[name] = 1000 * np.linalg.norm(track.joints - truth, axis=2).mean()
    # measured: cage 4.5 mm forward, 3.4 backward
    assert err["backward"] < err["forward"] + 1.0, err
    assert err["backward"] < 25, err


def test_the_keyframe_search_is_the_keyframe_pose_with_the_tracked_hints(monkeypatch):
    seen = {}
    monkeypatch.setattr(two_way, "keyframe_pose", lambda t, f, **kw: seen.update(kw) or "found")
    near = (np.eye(3)[None].repeat(31, axis=0), np.zeros(3))
    found = two_way.keyframe_search(
        "template", "frame", near=near, lost=("torso", "left_arm"), exclude_trials=("05_03",)
    )
    # the lost rule's parts as they are (a lost torso: the search leaves the heading out)
    assert found == "found" and seen["lost"] == ("torso", "left_arm")
    assert seen["near"] is near and seen["exclude_trials"] == ("05_03",)


@pytest.mark.slow
def test_the_pass_runs_on_a_clean_4d_capture_with_the_hold_and_the_refinement(
    walk, thrown, tmp_path, monkeypatch
):
    """The walk's true surfaces as a folder of meshes (a clean 4D capture, as ``track
    FOLDER`` reads it): the run of thrown arms is replaced, each hypothesis's skeleton held
    against the files' surface and its output refined as rigidly as possible, frame to
    frame, as the forward pass does there."""
    from meshmocap.geometry.refine import ArapRefiner
    from meshmocap.io.capture import SequenceCapture
    from meshmocap.io.meshes import write_mesh

    files = tmp_path / "meshes"
    files.mkdir()
    for f in walk:
        write_mesh(files / f"{f.index:05d}.ply", f.truth.vertices, walk.truth_faces)
    seq = SequenceCapture(files)
    folder = tmp_path / "track"
    shutil.copytree(thrown[0], folder)
    body = thrown[1]

    def search(template, frame, **hints):  # the files hold no truth: the walk's, by number
        truth = walk[int(frame.index)].truth
        return InitResult(truth.rotations, truth.root, 0.0, "truth", ())

    monkeypatch.setattr(two_way, "keyframe_search", search)
    tracker = make_tracker("articulated_icp", max_iter=5)
    tracker.setup(body.light)
    refiner = ArapRefiner(body.light.V, body.light.F, iterations=4)
    truth = np.stack([f.truth.vertices for f in walk])
    before = read_track(folder)
    res = two_way_pass(
        tracker,
        body,
        seq,
        folder,
        frames=range(len(seq)),
        refiner=refiner,
        hold=True,
        show_progress=False,
    )
    after = read_track(folder)
    assert res.runs == ((3, 6),) and res.flagged == (4, 0)
    changed = {i for c in res.changed for i in range(c["frames"][0], c["frames"][1] + 1)}
    assert {3, 4, 5, 6} <= changed
    err = lambda t: 1000 * np.linalg.norm(t.vertices - truth, axis=2).mean(axis=1)  # noqa: E731
    # mm per vertex; measured: the thrown arms' frames 1.5–1.9 mm after (the files' own
    # surfaces, the hold and the refinement in each hypothesis)
    assert err(before)[3:7].min() > 10.0
    assert err(after)[3:7].max() < 5.0
