"""The cage tracker: Gram–Schmidt derivatives, manifold learning, tracking a short walk."""

import numpy as np
import pytest

from meshmocap.body.procedural import walk
from meshmocap.body.template import load_template
from meshmocap.errors import FormatError, InputError
from meshmocap.geometry.rotations import so3_exp
from meshmocap.io.results import read_state
from meshmocap.models.gplvm import GPLVM
from meshmocap.trackers.cage.options import manifold_digest
from meshmocap.trackers.cage.quad_frames import gram_schmidt_forward
from meshmocap.trackers.cage.tracker import CageOptions, CageTracker, learn_manifold
from meshmocap.trackers.cage.training_poses import library_poses
from meshmocap.trackers.driver import track_sequence
from meshmocap.trackers.options import TrackOptions

#: The papers' protocol (first pose from ground truth), no loss recovery: these tests are
#: about the tracker itself.


def truth_options(**fields) -> TrackOptions:
    """The record of these tests' tracks: the first pose from ground truth, no checks."""
    return TrackOptions(init="truth", recover=False, **fields)


RNG = np.random.default_rng(2)


def test_gram_schmidt_derivative_matches_finite_differences():
    a, b, da, db = RNG.normal(size=(4, 5, 3))
    R, dR = gram_schmidt_forward(a, b, da, db)
    assert np.allclose(np.swapaxes(R, 1, 2) @ R, np.eye(3), atol=1e-12)
    h = 1e-6
    fd = (
        gram_schmidt_forward(a + h * da, b + h * db, da, db)[0]
        - gram_schmidt_forward(a - h * da, b - h * db, da, db)[0]
    ) / (2 * h)
    assert np.allclose(dR, fd, atol=1e-8)  # central differences: O(h²) ≈ 1e-12 + rounding


@pytest.fixture(scope="module")
def setup(synth_capture):
    t = load_template("neutral_5k")
    motions = [walk(t, duration=2.0, fps=30.0, cadence=c) for c in (100.0, 120.0)]
    gp = learn_manifold(t, motions, n_components=2, n_samples=60)
    return t, gp, synth_capture("walk", stop=6)


def test_cage_tracker_follows_a_walk_and_resumes(setup, tmp_path):
    t, gp, cap = setup
    opts = CageOptions(local_iters=1, alternations=2)
    track = track_sequence(
        CageTracker(gp, opts), t, cap, tmp_path / "tr", truth_options(show_progress=False)
    )
    true = np.stack([f.truth.joints for f in cap])
    err = np.linalg.norm(track.joints - true, axis=2).mean(axis=1) * 1000
    # joints start exactly on the truth (their Green coordinates are taken there) and stay
    # within the 35 mm on this short walk (a manifold of the same generator)
    assert err[0] < 1e-6 and err.max() < 35.0
    assert track.meta["cage_body"] == "template"  # a bundled body: its own cage
    (tmp_path / "tr" / "frames" / "00005.npz").unlink()
    again = track_sequence(
        CageTracker(gp, opts), t, cap, tmp_path / "tr", truth_options(show_progress=False)
    )
    assert np.allclose(again.joints, track.joints, atol=1e-9)


@pytest.mark.slow
def test_a_frame_after_one_off_the_manifold_alternates_once_and_a_resumed_run_knows(
    setup, tmp_path
):
    """After a frame off the manifold the next alternates pose and shape
    ``off_alternations`` times; the flag is in the frame's state, so a run killed and resumed
    there tracks the same frame to the bit (without it, the resumed frame alternates twice)."""
    t, gp, cap = setup
    opts = CageOptions(local_iters=1, alternations=2, off_manifold=1e-9)  # every frame off
    run = truth_options(positions=range(3), show_progress=False)
    first = track_sequence(CageTracker(gp, opts), t, cap, tmp_path / "tr", run)
    assert np.all(first.energies["off_manifold"][1:] > 0)
    before = read_state(tmp_path / "tr", 2)
    assert read_state(tmp_path / "tr", 1)["off_manifold"]
    (tmp_path / "tr" / "frames" / "00002.npz").unlink()
    again = track_sequence(CageTracker(gp, opts), t, cap, tmp_path / "tr", run)
    after = read_state(tmp_path / "tr", 2)
    assert np.array_equal(again.joints, first.joints)
    assert all(np.array_equal(before[k], after[k]) for k in before)
    state = read_state(tmp_path / "tr", 1)
    n_iter = []  # Levenberg–Marquardt linearisations of frame 2
    for s in (state, {k: v for k, v in state.items() if k != "off_manifold"}):
        tr = CageTracker(gp, opts)
        tr.setup(t)
        tr.set_state(s)
        n_iter.append(tr.step(cap[2]).n_iter)
    assert n_iter[1] > n_iter[0]  # the flag forgotten: a second alternation


def test_the_body_the_cage_is_built_on_is_said(setup):
    t, gp, _ = setup
    tracker = CageTracker(gp, CageOptions(body="reference"))
    assert tracker.built_on is None  # not set up yet
    tracker.setup(t)
    assert tracker.built_on == "reference" and tracker.body is not t


def test_the_pelvis_stays_a_rotation_when_it_moves_on_at_its_velocity(setup, tmp_path):
    t, gp, cap = setup
    tr = CageTracker(gp, CageOptions(local_iters=1, alternations=1))
    state = tr.init(t, cap[0], cap[0].truth.rotations, cap[0].truth.root).state
    # a last motion of 0.2 rad and 5 cm, and a pelvis rounded off its rotation by 1e-6: the
    # constant-velocity start once multiplied such matrices, and their error grew from
    # 1e-12 to det 1.15 in 40 frames of a run (a sheared cage; the arms were lost)
    R = state["pelvis_R"] + 1e-6 * RNG.normal(size=(3, 3))
    state = {
        **state,
        "pelvis_R": R,
        "velocity_w": np.array([0.0, 0.0, 0.2]),
        "velocity_c": np.array([0.0, -0.05, 0.0]),
        "velocity_y": 1e-3 + 0 * state["local"],
    }
    tr.set_state(state)
    for k in (1, 2, 3):
        tr.step(cap[k])
        assert np.abs(tr.pelvis_R.T @ tr.pelvis_R - np.eye(3)).max() < 1e-12
        assert abs(np.linalg.det(tr.pelvis_R) - 1.0) < 1e-12


def test_options_and_learning_errors(setup):
    t, gp, _ = setup
    with pytest.raises(InputError, match="space must be one of"):
        CageOptions(space="cage")
    with pytest.raises(InputError, match="no motions"):
        learn_manifold(t, [])
    assert CageTracker(gp).options()["n_components"] == 2


def test_joints_ride_their_quads_when_asked(setup, tmp_path):
    t, gp, cap = setup
    opts = CageOptions(local_iters=1, alternations=2, joints="quads")
    track = track_sequence(
        CageTracker(gp, opts), t, cap, tmp_path / "tr", truth_options(show_progress=False)
    )
    true = np.stack([f.truth.joints for f in cap])
    err = np.linalg.norm(track.joints - true, axis=2).mean(axis=1) * 1000
    assert err[0] < 1e-6 and err.max() < 35.0  # each evaluation joint is a quad's rig joint


def test_a_folded_first_cage_falls_back_to_the_rest_cage(setup):
    t, gp, cap = setup
    R = np.tile(np.eye(3), (t.skeleton.n_joints, 1, 1))
    R[t.skeleton.names.index("LeftArm")] = so3_exp(np.radians(60.0) * np.array([0.0, 1.0, 0.0]))
    root = t.skeleton.rest_positions[0]
    tr = CageTracker(gp)
    r = tr.init(t, cap[0], R, root)  # the arm's tube folds into the chest: GC are metres off
    assert np.array_equal(tr.cage0, tr.oqr.rest_vertices)
    err = np.linalg.norm(r.joints - t.pose(R, root).eval_joints, axis=1)
    legs = [t.eval_skeleton.names.index(n) for n in ("left_knee", "right_ankle")]
    assert np.all(np.isfinite(r.joints)) and err[legs].max() < 1e-3
    tr.init(t, cap[0], cap[0].truth.rotations, cap[0].truth.root)  # a walk: its own cage
    assert not np.array_equal(tr.cage0, tr.oqr.rest_vertices)


def test_vertices_the_cage_cannot_place_leave_the_data_term(setup):
    t, gp, cap = setup
    tr = CageTracker(gp, CageOptions(surface="green"))
    I = np.tile(np.eye(3), (t.skeleton.n_joints, 1, 1))
    root = t.skeleton.rest_positions[0]
    tr.init(t, cap[0], I, root)  # rest pose: Green coordinates reproduce every vertex
    assert tr._keep.all()
    R = I.copy()
    R[t.skeleton.index("Head")] = so3_exp(np.radians(50.0) * np.array([1.0, 0.0, 0.0]))
    state = tr.init(t, cap[0], R, root).state  # the head bends inside the neck–head tube
    part = np.asarray(t.weights.argmax(axis=1)).ravel()[tr.sample]
    head = part == t.skeleton.index("Head")
    neck = np.isin(part, [t.skeleton.index(n) for n in ("Head", "Neck", "Neck1")])
    assert neck[~tr._keep].all() and (~tr._keep[head]).mean() > 0.5
    again = CageTracker(gp, CageOptions(surface="green"))
    again.setup(t)
    again.set_state(state)  # a resumed run keeps the same data term
    assert np.array_equal(again._keep, tr._keep)
    with pytest.raises(InputError, match="max_model_error"):
        CageOptions(max_model_error=0.0)


def test_options_identify_the_manifold_and_a_resume_with_another_is_refused(setup, tmp_path):
    t, gp, cap = setup
    digest = CageTracker(gp).options()["manifold"]
    assert digest == manifold_digest(gp) and len(digest) == 16
    assert manifold_digest(GPLVM.load(gp.save(tmp_path / "gp.npz"))) == digest  # saved as is
    motions = [walk(t, duration=2.0, fps=30.0, cadence=c) for c in (100.0, 120.0)]
    other = learn_manifold(t, motions, n_components=2, n_samples=50)
    assert manifold_digest(other) != digest
    opts = CageOptions(local_iters=0, alternations=1)
    frames = [0, 1]
    track_sequence(
        CageTracker(gp, opts),
        t,
        cap,
        tmp_path / "tr",
        truth_options(positions=frames, show_progress=False),
    )
    with pytest.raises(FormatError, match="other settings") as info:
        track_sequence(
            CageTracker(other, opts),
            t,
            cap,
            tmp_path / "tr",
            truth_options(positions=frames, show_progress=False),
        )
    assert "\n" not in str(info.value)
    with pytest.raises(InputError, match="manifold_digest: gp must be a fitted GPLVM"):
        manifold_digest(GPLVM(2))


@pytest.mark.slow
def test_a_manifold_of_other_motions_is_noticed_and_not_pulled_back_to(setup, tmp_path):
    """A manifold of modern-dance poses cannot explain a walk: its configuration fits the
    frames far worse than the tracked quads, so the frames are marked off the manifold
    (energy ``off_manifold``) and tracked without its pull; with ``off_manifold=0`` never,
    nor with a manifold of the walk's own generator."""
    t, gp, cap = setup
    own = track_sequence(
        CageTracker(gp, CageOptions(local_iters=1, alternations=1)),
        t,
        cap,
        tmp_path / "c",
        truth_options(positions=range(4), show_progress=False),
    )
    assert not np.any(own.energies["off_manifold"] > 0)
    lib = library_poses(t, 400)
    dance = lib.configurations[lib.groups == "modern dance"][:60]
    other = GPLVM(2, back_constraint="rbf", max_iter=100, random_state=0).fit(dance)
    frames = range(4)
    opts = dict(local_iters=1, alternations=1)
    off = track_sequence(
        CageTracker(other, CageOptions(**opts)),
        t,
        cap,
        tmp_path / "a",
        truth_options(positions=frames, show_progress=False),
    ).energies["off_manifold"]
    assert np.sum(off[1:] > 0) >= 2
    never = CageTracker(other, CageOptions(off_manifold=0.0, **opts))
    off = track_sequence(
        never, t, cap, tmp_path / "b", truth_options(positions=frames, show_progress=False)
    ).energies["off_manifold"]
    assert not np.any(off[1:] > 0)
