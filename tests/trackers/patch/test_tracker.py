"""The patch tracker and the sequence driver on a short synthetic walk."""

import json
import shutil
from dataclasses import replace

import numpy as np
import pytest

from meshmocap.body.template import load_template
from meshmocap.errors import InputError
from meshmocap.io.results import done_frames, read_track
from meshmocap.trackers.driver import track_sequence
from meshmocap.trackers.options import TrackOptions
from meshmocap.trackers.patch.tracker import (
    STAGES,
    PatchOptions,
    PatchTracker,
    surface_training_sample,
)

#: The papers' protocol (first pose from ground truth), no loss recovery: these tests are
#: about the tracker itself.


def truth_options(**fields) -> TrackOptions:
    """The record of these tests' tracks: the first pose from ground truth, no checks."""
    return TrackOptions(init="truth", recover=False, **fields)


@pytest.fixture(scope="module")
def walk(synth_capture):
    """The session's neutral_5k walk, 7 frames, with its template."""
    return synth_capture("walk", stop=7), load_template("neutral_5k")


@pytest.fixture(scope="module")
def tracked(walk, tmp_path_factory):
    cap, t = walk
    out = tmp_path_factory.mktemp("track")
    opts = PatchOptions(n_patches=120, max_iter=6)
    return (
        track_sequence(PatchTracker(opts), t, cap, out, truth_options(show_progress=False)),
        out,
        opts,
    )


def test_patch_tracker_follows_a_walk(walk, tracked):
    cap, _ = walk
    track, _, _ = tracked
    true = np.stack([f.truth.joints for f in cap])
    err = np.linalg.norm(track.joints - true, axis=2).mean(axis=1) * 1000  # mm per frame
    # 4-camera hulls are fat (phantom volume); over 7 frames the tracker stays within the
    # issue's 35 mm budget (the benchmark measures whole clips). Frame 0 is the ground-truth
    # pose; its reported joints are the default blended read-out of the patches fitted to
    # it, within 2 mm (measured 0.8 mm; the skeleton state itself is exact there).
    assert err[0] < 2.0 and err.max() < 35.0
    assert track.healthy.all() and np.isfinite(track.vertices).all()
    assert set(track.energies) >= {"data", "rigidity", "bone", "total"}


def test_stage_breakdown_accounts_for_the_step_time(walk, tmp_path):
    """Every stage is timed, and the stages are parts of the frame time the driver measured
    (which also covers reading the frame, the checks and the call: how much more depends
    on the machine, so only the order is claimed)."""
    cap, t = walk
    tracker = PatchTracker(PatchOptions(n_patches=120, max_iter=3))
    track = track_sequence(
        tracker, t, cap, tmp_path / "tr", truth_options(positions=range(3), show_progress=False)
    )
    assert tracker.n_steps == 2 and set(tracker.stage_seconds) == set(STAGES)
    assert all(v > 0 for v in tracker.stage_seconds.values())
    assert sum(tracker.stage_seconds.values()) <= track.seconds[1:].sum()


def test_part_matching_restricts_only_on_bone_points(walk):
    """With ``part_matching="on_bone"`` near-joint points lose their label (−1: any patch);
    with "none" no label reaches the E-step; "all" keeps every label."""
    cap, t = walk
    found = {}
    for mode in ("all", "on_bone", "none"):
        tracker = PatchTracker(PatchOptions(n_patches=120, part_matching=mode))
        tracker.init(t, cap[0], cap[0].truth.rotations, cap[0].truth.root)
        Y, N, rng = tracker.observations(cap[1])
        found[mode] = tracker.classify(Y, N, rng)[2]
    assert found["none"] is None
    assert (found["all"] >= 0).all()
    free = found["on_bone"] < 0
    assert 0 < free.sum() < len(free)  # some near-joint points, most on bone
    assert np.array_equal(found["on_bone"][~free], found["all"][~free])


def test_interrupted_run_resumes_to_the_same_result(walk, tracked, tmp_path):
    cap, t = walk
    track, out, opts = tracked
    part = tmp_path / "track"
    shutil.copytree(out, part)
    for i in (5, 6):
        (part / "frames" / f"{i:05d}.npz").unlink()
    assert done_frames(part) == [0, 1, 2, 3, 4]
    again = track_sequence(PatchTracker(opts), t, cap, part, truth_options(show_progress=False))
    assert np.allclose(again.joints, track.joints, atol=1e-9)  # seeded per frame: identical
    with pytest.raises(Exception, match="other settings"):
        track_sequence(
            PatchTracker(PatchOptions(n_patches=90)),
            t,
            cap,
            part,
            truth_options(show_progress=False),
        )


class _Flaky(PatchTracker):
    """Fails on frame 3 like a singular system would."""

    def step(self, frame):
        if frame.index == 3:
            raise np.linalg.LinAlgError("singular matrix")
        return super().step(frame)


def test_failed_frame_is_flagged_and_tracking_continues(walk, tmp_path):
    cap, t = walk
    opts = PatchOptions(n_patches=120, max_iter=4)
    track = track_sequence(
        _Flaky(opts),
        t,
        cap,
        tmp_path / "tr",
        truth_options(positions=range(5), show_progress=False),
    )
    assert track.healthy.tolist() == [True, True, True, False, True]
    assert np.array_equal(track.joints[3], track.joints[2])  # the last good result repeated
    assert np.isfinite(track.joints).all()
    flagged = read_track(tmp_path / "tr")
    assert not flagged.healthy[3]


def test_options_are_validated():
    with pytest.raises(InputError, match="classifier must be one of"):
        PatchOptions(classifier="forest")
    with pytest.raises(InputError, match="keep_fraction"):
        PatchOptions(keep_fraction=0.0)
    with pytest.raises(InputError, match="part_matching must be one of"):
        PatchOptions(part_matching="some")
    with pytest.raises(InputError, match="lambda_reverse must be a number ≥ 0, found nan"):
        PatchOptions(lambda_reverse=float("nan"))
    with pytest.raises(InputError, match="reverse_cap must be a number > 0, found 0"):
        PatchOptions(reverse_cap=0)
    with pytest.raises(InputError, match="reverse_scale must be a number > 0, found -1"):
        PatchOptions(reverse_scale=-1)
    with pytest.raises(InputError, match=r"fast_iter_scale must be a number ≥ 1, found 0\.5"):
        PatchOptions(fast_iter_scale=0.5)
    with pytest.raises(InputError, match="fast_motion must be a number > 0, found 0"):
        PatchOptions(fast_motion=0)
    with pytest.raises(InputError, match="max_iter must be an integer ≥ 1, found 0"):
        PatchOptions(max_iter=0)
    with pytest.raises(InputError, match="relaxation must be a number > 0, found 0"):
        PatchOptions(relaxation=0)


def _after_motion(t, frame, opts: PatchOptions, moved: float) -> PatchTracker:
    """A tracker seated on ``frame`` at its true pose, whose last frame 'moved' one joint
    ``moved`` metres (no prediction: the fake motion stays out of the fit)."""
    tracker = PatchTracker(opts)
    tracker.init(t, frame, frame.truth.rotations, frame.truth.root)
    R, c, X = tracker.prev
    X = X.copy()
    X[5, 0] -= moved
    tracker.prev = (R, c, X)
    tracker.opts = replace(opts, prediction="none")
    return tracker


@pytest.mark.parametrize(("moved", "relaxed"), [(0.0, 1.7), (0.08, 1.0)])
def test_steps_after_the_first_are_over_relaxed(walk, monkeypatch, moved, relaxed):
    """``relaxation``: a slow frame's first Gauss–Newton step is taken as solved, every later
    one ``relaxation`` times over; a fast frame's (a joint moved 8 cm) all as solved."""
    from meshmocap.trackers.patch import tracker as module

    cap, t = walk
    solved, applied = [], []
    solve, apply = module.System.solve, PatchTracker._apply
    monkeypatch.setattr(
        module.System, "solve", lambda s, *a: solved.append(solve(s, *a)) or solved[-1]
    )
    monkeypatch.setattr(PatchTracker, "_apply", lambda s, d: applied.append(d) or apply(s, d))
    opts = PatchOptions(n_patches=120, max_iter=3, tol=0.0, relaxation=1.7, fast_iter_scale=1)
    tracker = _after_motion(t, cap[0], opts, moved)
    assert tracker.step(cap[1]).n_iter == 3
    assert len(solved) == len(applied) == 3
    np.testing.assert_array_equal(applied[0], solved[0])
    for a, s in zip(applied[1:], solved[1:], strict=True):
        np.testing.assert_allclose(a, relaxed * s, rtol=1e-15, atol=0)


@pytest.mark.parametrize(
    ("moved", "scale", "expected"), [(0.02, 2.0, 3), (0.08, 2.0, 6), (0.08, 1.0, 3)]
)
def test_fast_frames_get_more_iterations(walk, moved, scale, expected):
    """A frame after one where a joint moved more than ``fast_motion`` (5 cm) runs
    ``fast_iter_scale × max_iter`` EM iterations; ``tol=0`` never stops early."""
    cap, t = walk
    opts = PatchOptions(n_patches=120, max_iter=3, tol=0.0, fast_iter_scale=scale)
    tracker = _after_motion(t, cap[0], opts, moved)
    assert tracker.step(cap[1]).n_iter == expected


def test_track_and_eval_commands(walk, tmp_path, capsys):
    from meshmocap.cli import main

    cap, _ = walk
    out = tmp_path / "tr"
    args = [
        "track",
        str(cap.path),
        "--template",
        "neutral_5k",
        "--init",
        "truth",
        "--out",
        str(out),
    ]
    assert (
        main(
            [
                *args,
                "--frames",
                "0:4",
                "--n-patches",
                "100",
                "--max-iter",
                "4",
                "--outlier-sigmas",
                "2.5",
                "--fast-iter-scale",
                "1.5",
                "--joint-readout",
                "skeleton",
            ]
        )
        == 0
    )
    assert "tracked 4 frames with patch" in capsys.readouterr().out
    meta = json.loads((out / "track.json").read_text())
    assert meta["options"]["outlier_sigmas"] == 2.5 and meta["options"]["n_patches"] == 100
    assert meta["options"]["fast_iter_scale"] == 1.5
    assert meta["options"]["joint_readout"] == "skeleton"
    bad = [*args[:-1], str(tmp_path / "bad"), "--outlier-sigmas", "0"]
    assert main(bad) == 2
    assert (
        "--outlier-sigmas: expected a number above 0 up to 100, found '0'"
        in capsys.readouterr().err
    )
    assert main(["eval", str(cap.path), str(out), "--surface-frames", "1"]) == 0
    assert "3D joint error" in capsys.readouterr().out
    assert main(["track", str(cap.path), "--method", "nope", "--out", str(out)]) == 2
    assert "method must be one of" in capsys.readouterr().err


def test_reverse_term_measures_vertex_to_data_distances(walk):
    """The reverse term is the (Cauchy-weighted: weight 1 − 1e-7 at 10 µm) mean squared
    distance from the sampled template vertices to their nearest compatible observation:
    observations = the fitted surface moved 10 µm (less than half the ≥ 0.2 mm spacing of
    neutral_5k's vertices, so each vertex's nearest observation is its own copy) give
    1e-10 m²; beyond ``reverse_cap`` nothing."""
    from types import SimpleNamespace

    from meshmocap.trackers.patch.solver import System
    from meshmocap.trackers.patch.terms import Correspondences, Iterate, ReverseTerm

    cap, t = walk
    tracker = PatchTracker(PatchOptions(n_patches=120))
    tracker.init(t, cap[0], cap[0].truth.rotations, cap[0].truth.root)
    Vc, Nc = tracker.own_vertices()
    term = ReverseTerm(10.0, cap=0.3, cauchy_scale=0.03)
    none = Correspondences(*(np.zeros(0, int),) * 2, np.zeros(0), *(np.zeros((0, 3)),) * 2)

    def reverse(Y, cameras=()):
        frame = SimpleNamespace(cameras=list(cameras), silhouettes=[])
        fd = tracker.frame_data(Y, Nc, frame, tracker.X)
        it = Iterate(fd, tracker.R, tracker.c, tracker.X, Vc, Nc, none)
        return term.add(System.empty(tracker.pattern), it)

    for shift, expected in (([0.0, 0.0, 1e-5], 1e-10), ([2.0, 0.0, 0.0], 0.0)):
        e = reverse(Vc + shift)
        assert e == pytest.approx(expected, rel=1e-6, abs=1e-18)  # rounding of 1 m coordinates
    assert len(tracker.reverse_sample) >= 2000  # every k-th of the 5000 vertices
    # vertices a camera does not see are left alone (no hull exists there)
    rig = list(cap.cameras)
    Y = Vc + [0.0, 0.0, 1e-5]
    assert reverse(Y, rig) == pytest.approx(1e-10)
    blind = [replace(rig[0], t=rig[0].t + [0.0, 0.0, -50.0])]  # the body is behind it
    assert reverse(Y, blind) == 0.0


def test_skeleton_floor_is_zero_for_rigid_poses_and_largest_on_the_torso():
    """The bone binding is exact when the body moves rigidly (floor < 1 µm on the rest pose
    turned and shifted); on the template's training poses the pelvis and thorax, which no
    patch follows rigidly, have the largest floors (measured 41 and 32 mm against 4 mm for
    the knees)."""
    from meshmocap.body.joint_regressor import training_poses
    from meshmocap.geometry.rotations import so3_exp
    from meshmocap.trackers.patch.model import build_patch_model, skeleton_floor

    t = load_template("neutral_5k")
    m = build_patch_model(t, n_patches=150)
    R = so3_exp(np.array([[0.0, 0.0, 0.0], [0.2, -0.5, 1.0]]))
    shift = np.array([[0.0, 0.0, 0.0], [0.3, 1.0, -0.2]])
    X0 = t.eval_skeleton.rest_positions
    V = np.einsum("tij,nj->tni", R, t.V) + shift[:, None]
    X = np.einsum("tij,kj->tki", R, X0) + shift[:, None]
    assert skeleton_floor(m, V, X).max() < 1e-6
    V, X = training_poses(t, step=12)
    floor = dict(zip(t.eval_skeleton.names, skeleton_floor(m, V, X), strict=True))
    assert min(floor["pelvis"], floor["thorax"]) > 3 * max(floor["left_knee"], floor["right_knee"])


@pytest.mark.parametrize("readout", ["skeleton", "surface", "blend"])
def test_joint_readout_chooses_the_reported_joints(walk, readout):
    """With "skeleton" the tracker reports its skeleton (the state), with "surface" the
    regressor applied to the output mesh, with "blend" a per-joint mix of the two: mostly
    surface for the pelvis (floor 41 mm), mostly skeleton for the knees (4 mm)."""
    cap, t = walk
    tracker = PatchTracker(PatchOptions(n_patches=120, max_iter=2, joint_readout=readout))
    tracker.init(t, cap[0], cap[0].truth.rotations, cap[0].truth.root)
    r = tracker.step(cap[1])
    X = r.state["X"]
    if readout == "skeleton":
        assert tracker.regressor is None and np.array_equal(r.joints, X)
        return
    surface = tracker.regressor @ r.vertices
    w = tracker.surface_weight
    if readout == "surface":
        assert np.array_equal(w, np.ones(len(w)))
    else:
        named = dict(zip(t.eval_skeleton.names, w, strict=True))
        assert named["pelvis"] > 0.8 and named["left_knee"] < 0.3 and np.all((w > 0) & (w < 1))
    # the mix, moved the least to hold the first frame's bone lengths (to 1 µm): the move
    # is normal to the length constraints, in the span of their gradients
    mix = X + w[:, None] * (surface - X)
    pairs = tracker.pairs
    held = np.linalg.norm(r.joints[pairs[:, 0]] - r.joints[pairs[:, 1]], axis=1)
    assert np.abs(held - tracker.lengths).max() < 1e-6
    u = (r.joints[pairs[:, 0]] - r.joints[pairs[:, 1]]) / held[:, None]
    J = np.zeros((len(pairs), r.joints.size))
    rows, xyz = np.arange(len(pairs))[:, None], np.arange(3)
    J[rows, 3 * pairs[:, :1] + xyz], J[rows, 3 * pairs[:, 1:] + xyz] = u, -u
    move = (r.joints - mix).ravel()
    normal = J.T @ np.linalg.lstsq(J.T, move, rcond=None)[0]
    assert np.linalg.norm(move - normal) < 1e-6 * np.linalg.norm(move)
    assert np.abs(r.joints - mix).max() < 0.02  # a small correction (centimetres at most)


def test_joint_readout_option_is_validated():
    with pytest.raises(InputError, match=r"joint_readout must be one of \['blend'"):
        PatchOptions(joint_readout="mean")


def test_classifier_trains_on_points_spread_by_area_not_by_vertices():
    """A unit square meshed finely on its left half (45 vertices) and as one quad on its
    right half (2 more): half of the training points on each half, each labelled by its
    face's nearest corner; the same points again from the same seed."""
    n = 8  # the left half: an (n/2 + 1) x (n + 1) grid of spacing 1/n
    cols = n // 2 + 1
    V = [(x / n, y / n, 0.0) for y in range(n + 1) for x in range(cols)]
    V = np.array([*V, (1.0, 0.0, 0.0), (1.0, 1.0, 0.0)])
    F = []
    for y in range(n):
        for x in range(cols - 1):
            a = cols * y + x
            F += [(a, a + 1, a + cols + 1), (a, a + cols + 1, a + cols)]
    right = [cols - 1 + cols * y for y in range(n + 1)]  # the left half's right edge
    lo, hi = len(V) - 2, len(V) - 1
    F += [(right[k], lo, right[k + 1]) for k in range(n // 2)]
    F += [(right[k], hi, right[k + 1]) for k in range(n // 2, n)]
    F += [(right[n // 2], lo, hi)]
    F = np.array(F)
    cls = (V[:, 0] > 0.6).astype(np.int64)
    faces, bary, labels = surface_training_sample(V, F, cls, seed=3)
    X = np.einsum("nk,nka->na", bary, V[F[faces]])
    assert len(X) == len(V)
    share = float((X[:, 0] > 0.5).mean())  # the vertices: 2 of 47 there
    # binomial, 47 draws of p = 1/2: the seeded draw is within 2 standard deviations
    assert abs(share - 0.5) < 2 * np.sqrt(0.25 / len(V))
    assert np.array_equal(labels, cls[F[faces, bary.argmax(axis=1)]])
    again = surface_training_sample(V, F, cls, seed=3)
    assert all(np.array_equal(a, b) for a, b in zip(again, (faces, bary, labels), strict=True))


@pytest.mark.parametrize("max_points", [500, 10**6])
def test_observations_sample_the_points_with_their_normals(walk, max_points):
    """A mesh frame's sampled points come with the normals every point has (only the
    sample's are computed): the frame's points and normals, drawn by the frame's seed."""
    from meshmocap.estimate.recovery.observe import frame_points

    cap, _ = walk
    Y, N, _ = PatchTracker(PatchOptions(max_points=max_points)).observations(cap[2])
    P, NP = frame_points(cap[2])
    pick = np.arange(len(P))
    if len(P) > max_points:
        pick = np.random.default_rng([0, 2]).choice(len(P), max_points, replace=False)
    np.testing.assert_array_equal(Y, P[pick])
    np.testing.assert_array_equal(N, NP[pick])


def test_hold_places_the_patches_on_the_surface_given(walk):
    """``hold`` fits the patches to the template posed by the held pose, or (``surface``)
    to another body in that pose: the output then follows that body, and the joints stay
    the skeleton's."""
    cap, t = walk
    tracker = PatchTracker(PatchOptions(n_patches=120))
    f0, f1 = cap[0], cap[1]
    tracker.init(t, f0, f0.truth.rotations, f0.truth.root)
    R, root = f1.truth.rotations, f1.truth.root
    posed = t.pose(R, root)
    skin = tracker.hold(f1, R, root).vertices
    body = posed.V + [0.0, 0.0, 0.01]  # another body in the same pose: 1 cm higher
    held = tracker.hold(f1, R, root, surface=body)
    near = [np.linalg.norm(V - body, axis=1).mean() for V in (held.vertices, skin)]
    assert near[0] < 0.3 * near[1]  # the patches follow the body given, not the skin
    np.testing.assert_array_equal(held.state["X"], posed.eval_joints)
