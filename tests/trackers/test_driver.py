"""The driver tracks a light body and writes the full one: a 12k-vertex template is tracked
on its 5,000-vertex copy, the track holds the full template's vertices, as close to the
truth as tracking the full template gives. The start is a record: the first frame's flag
and message are made from it, and the evaluation reads it back."""

import json

import numpy as np
import pytest

from meshmocap.analysis.evaluate import evaluate, summary
from meshmocap.body.light import tracking_body
from meshmocap.body.template import load_template
from meshmocap.estimate.pose.start import start_description, start_message
from meshmocap.io.results import LIGHT_FILE, read_frame_arrays
from meshmocap.io.start import Start
from meshmocap.trackers.driver import track_sequence
from meshmocap.trackers.options import TrackOptions
from meshmocap.trackers.registry import make_tracker

N = 5


@pytest.fixture(scope="module")
def walk(walk_full):
    """The session's walk of the full neutral template (:data:`N` frames)."""
    assert len(walk_full) == N
    return walk_full


def _track(walk, out, light):
    t = load_template("neutral")
    body = tracking_body(t, n_vertices=light)
    tracker = make_tracker("articulated_icp", template=body.light, max_iter=5)
    return track_sequence(
        tracker,
        t,
        walk,
        out,
        TrackOptions(init="truth", recover=False, show_progress=False, light=light),
    )


def test_the_full_template_is_read_out_of_the_tracked_light_one(walk, tmp_path):
    t = load_template("neutral")
    light = _track(walk, tmp_path / "light", 5000)
    full = _track(walk, tmp_path / "full", None)
    meta = json.loads((tmp_path / "light" / "track.json").read_text())
    assert meta["tracked_vertices"] == tracking_body(t).light.n_vertices < 5100
    assert light.vertices.shape == full.vertices.shape == (N, t.n_vertices, 3)
    # the frames hold the light body (less than half the bytes), read_track reads out
    assert read_frame_arrays(tmp_path / "light", 1)["vertices"].shape == (
        meta["tracked_vertices"],
        3,
    )
    assert (tmp_path / "light" / LIGHT_FILE).is_file()
    assert not (tmp_path / "full" / LIGHT_FILE).exists()
    truth_V = np.stack([f.truth.vertices for f in walk])
    truth_J = np.stack([f.truth.joints for f in walk])
    for track in (light, full):
        assert track.healthy.all()
    ev = {
        k: (
            1000 * np.linalg.norm(tr.vertices - truth_V, axis=2).mean(),
            1000 * np.linalg.norm(tr.joints - truth_J, axis=2).mean(),
        )
        for k, tr in (("light", light), ("full", full))
    }
    # the surface and the joints as close to the truth as tracking the full body (1 mm);
    # measured: surface 8.8 mm light, 9.9 mm full
    assert ev["light"][0] < ev["full"][0] + 1.0 and ev["light"][1] < ev["full"][1] + 1.0
    assert ev["light"][0] < 15 and ev["light"][1] < 15


@pytest.mark.parametrize("confident", [True, False])
def test_the_start_record_sets_the_first_frames_flag_and_message(walk, tmp_path, confident):
    t = load_template("neutral")
    truth = walk[0].truth
    start = Start(0, truth.rotations, truth.root, "search", confident, "02_02:2@0°", 0.03, 0.04)
    tracker = make_tracker("articulated_icp", template=tracking_body(t).light, max_iter=3)
    track = track_sequence(
        tracker, t, walk, tmp_path, TrackOptions(positions=[0, 1], start=start, show_progress=False)
    )
    assert track.flags[0] == (() if confident else ("lost",))  # from the record, not the text
    assert track.messages[0] == start_message(start)
    assert ("uncertain start" in track.messages[0]) is not confident
    assert track.start.R.tobytes() == truth.rotations.tobytes() and track.start.label == start.label
    ev = evaluate(track, walk, silhouettes=False, surface_frames=0)
    assert ev.start is track.start and ev.init == start_description(start)
    assert f"init {start_description(start)}" in summary(ev)
    # from ground truth: recorded as such, never flagged
    tracker = make_tracker("articulated_icp", template=tracking_body(t).light, max_iter=3)
    truth_track = track_sequence(
        tracker,
        t,
        walk,
        tmp_path / "truth",
        TrackOptions(positions=[0], init="truth", show_progress=False),
    )
    assert truth_track.start.source == "truth" and truth_track.flags == ((),)


def test_a_timer_records_every_frames_stages_and_changes_no_result(walk, tmp_path):
    """With a timer the driver books each tracked frame's read, observation, step (and the
    tracker's own stages), checks and write; the track is the one it writes without."""
    from meshmocap._timing import FRAME_STAGES, StageTimer
    from meshmocap.trackers.articulated_icp import STAGES

    t = load_template("neutral_5k")

    def run(out, timer):
        tracker = make_tracker("articulated_icp", template=t, max_iter=5)
        return track_sequence(
            tracker,
            t,
            walk,
            out,
            TrackOptions(init="truth", show_progress=False, light=None),
            timer=timer,
        )

    timer = StageTimer()
    timed, plain = run(tmp_path / "timed", timer), run(tmp_path / "plain", None)
    np.testing.assert_array_equal(timed.joints, plain.joints)
    np.testing.assert_array_equal(timed.vertices, plain.vertices)
    assert len(timer.frames) == len(timer.cpu) == N - 1  # every frame after the first
    for rec in timer.frames:
        assert set(FRAME_STAGES) <= set(rec) and all(v >= 0 for v in rec.values())
        assert {f"step.{s}" for s in STAGES} <= set(rec)
        # the tracker's stages are parts of the step
        assert sum(rec[f"step.{s}"] for s in STAGES) <= rec["step"] * 1.01 + 1e-4
    # from frame 2 the hull is read and its points derived before the step asks for them
    assert timer.reads and "surface" in timer.derived
    assert "in all" in timer.summary()


def test_the_checks_start_the_pose_of_an_articulated_track_at_the_trackers_own(walk, tmp_path):
    """The articulated ICP's state holds its pose on the recovery's skeleton: the pose of
    the tracked mesh the checks fit starts there, and stays there (its mesh is that pose's)."""
    t = load_template("neutral_5k")
    tracker = make_tracker("articulated_icp", template=t, max_iter=5)
    out = tmp_path / "icp"
    track = track_sequence(
        tracker, t, walk, out, TrackOptions(init="truth", show_progress=False, light=None)
    )
    for i in track.frames[1:]:
        z = read_frame_arrays(out, int(i))
        R, root = z["state_pose_R"], z["state_pose_root"]
        assert np.abs(t.pose(R, root).V - z["vertices"]).max() < 1e-3
        assert np.abs(R - z["state_R"]).max() < 1e-3
        assert np.abs(root - z["state_root"]).max() < 1e-4


def test_the_refined_surface_leaves_the_joints_and_the_state_as_tracked(walk, tmp_path):
    """``refine`` moves only the output surface, towards each frame's own observations:
    the joints and everything the next frame starts from are the skeleton's."""
    from meshmocap.estimate.recovery.observe import frame_points

    t = load_template("neutral_5k")

    def run(out, refine):
        tracker = make_tracker("articulated_icp", template=t, max_iter=5)
        return track_sequence(
            tracker,
            t,
            walk,
            out,
            TrackOptions(init="truth", show_progress=False, light=None, refine=refine),
        )

    refined, plain = run(tmp_path / "refined", "on"), run(tmp_path / "plain", "off")
    rigid = run(tmp_path / "rigid", "arap")
    assert json.loads((tmp_path / "refined" / "track.json").read_text())["refine_surface"]
    assert rigid.meta["refine_surface"] == "arap"
    np.testing.assert_array_equal(rigid.joints, plain.joints)
    # by default a capture folder's visual hulls (larger than the body) are not followed
    tracker = make_tracker("articulated_icp", template=t, max_iter=5)
    auto = track_sequence(
        tracker,
        t,
        walk,
        tmp_path / "auto",
        TrackOptions(init="truth", show_progress=False, light=None),
    )
    assert auto.meta["refine_surface"] is False
    np.testing.assert_array_equal(auto.vertices, plain.vertices)
    np.testing.assert_array_equal(refined.joints, plain.joints)
    moved = np.linalg.norm(refined.vertices - plain.vertices, axis=2)
    assert moved[1:].max() > 1e-3 and moved.max() <= 0.05 + 1e-6  # never beyond reach
    # each refined frame lies nearer its own hull's surface than the skeleton's skin
    from pykdtree.kdtree import KDTree

    for k in range(1, N):
        P, _ = frame_points(walk[k])
        near = [KDTree(P).query(V[k])[0].mean() for V in (refined.vertices, plain.vertices)]
        assert near[0] < near[1]
        assert KDTree(P).query(rigid.vertices[k])[0].mean() < near[1]


@pytest.mark.slow
def test_a_4d_capture_holds_the_skeleton_against_its_meshes(mesh_folder, small_walk, tmp_path):
    """On mesh files (a 4D capture) the patch tracker's pose is fitted every frame against
    the observed surface, from the pose of its own (``hold_skeleton`` in ``track.json``);
    the joints stay on the truth; a capture folder's hulls are not held; articulated ICP is
    held as well."""
    from meshmocap.io.capture import SequenceCapture

    t = load_template("neutral_5k")
    seq = SequenceCapture(mesh_folder)
    tracker = make_tracker("patch", template=t)
    held = track_sequence(
        tracker,
        t,
        seq,
        tmp_path / "held",
        TrackOptions(
            show_progress=False,
            light=None,
            positions=[0, 1, 2],
            start=Start(0, small_walk[0].truth.rotations, small_walk[0].truth.root, "truth"),
        ),
    )
    assert held.meta["hold_skeleton"] is True and all(held.healthy)
    truth = np.stack([small_walk[k].truth.joints for k in range(3)])
    err = np.linalg.norm(held.joints - truth, axis=2)
    assert err.mean() < 0.01  # measured 0.6 mm
    tracker = make_tracker("articulated_icp", template=t, max_iter=5)
    hulls = track_sequence(
        tracker,
        t,
        small_walk,
        tmp_path / "hulls",
        TrackOptions(init="truth", show_progress=False, light=None, positions=[0, 1]),
    )
    assert hulls.meta["hold_skeleton"] is False
    icp = make_tracker("articulated_icp", template=t, max_iter=5)
    plain = track_sequence(
        icp,
        t,
        seq,
        tmp_path / "icp",
        TrackOptions(
            show_progress=False,
            light=None,
            positions=[0, 1],
            start=Start(0, small_walk[0].truth.rotations, small_walk[0].truth.root, "truth"),
        ),
    )
    assert plain.meta["hold_skeleton"] is True and all(plain.healthy)


def test_a_clean_4d_capture_is_refined_with_more_steps_and_other_files_as_before():
    """Mesh files of one connectivity (``clean``) get ``CLEAN_4D_ITERATIONS`` local and
    global steps; hull meshes and point clouds as files the refiner's default; a capture
    folder none by default."""
    from meshmocap.geometry.refine import ArapRefiner
    from meshmocap.trackers.driver import CLEAN_4D_ITERATIONS, output_refiner

    t = load_template("neutral_5k")
    default = ArapRefiner.__init__.__kwdefaults__["iterations"]
    assert default < CLEAN_4D_ITERATIONS
    assert output_refiner(t, four_d=True, clean=True).iterations == CLEAN_4D_ITERATIONS
    assert output_refiner(t, refine="arap", four_d=True).iterations == default
    assert output_refiner(t, four_d=False) is None
