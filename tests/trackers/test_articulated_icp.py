"""The articulated ICP baseline: exact Jacobians, tracking a short synthetic walk, resuming."""

import shutil
from types import SimpleNamespace

import numpy as np
import pytest

from meshmocap.body.articulated import (
    FIXED_JOINTS,
    apply_increment,
    articulated_model,
    nearest_compatible,
    pose_points,
    residual_jacobian,
    subtree_matrix,
)
from meshmocap.body.skeleton import forward_kinematics
from meshmocap.body.template import load_template
from meshmocap.errors import FitError, InputError
from meshmocap.geometry.mesh import vertex_normals
from meshmocap.geometry.rotations import so3_exp
from meshmocap.io.results import done_frames, read_state
from meshmocap.trackers.articulated_icp import (
    ArticulatedICP,
    ICPOptions,
    data_to_model,
    relaxation,
)
from meshmocap.trackers.driver import track_sequence
from meshmocap.trackers.options import TrackOptions
from meshmocap.trackers.registry import make_tracker

#: The papers' protocol (first pose from ground truth), no loss recovery: these tests are
#: about the tracker itself.


def truth_options(**fields) -> TrackOptions:
    """The record of these tests' tracks: the first pose from ground truth, no checks."""
    return TrackOptions(init="truth", recover=False, **fields)


N_FRAMES = 8  # 60 fps: 0.13 s of walking


@pytest.fixture(scope="module")
def template():
    return load_template("neutral_5k")


@pytest.fixture(scope="module")
def posed(template):
    """A model of 200 points and a random pose far from rest (float64)."""
    rng = np.random.default_rng(3)
    J = template.skeleton.n_joints
    R = so3_exp(rng.normal(scale=0.3, size=(J, 3)))
    return articulated_model(template, n_points=200, seed=1), R, np.array([0.1, -0.2, 0.9])


def _numeric(f, n, eps=1e-6):
    """Central differences of ``f(delta)`` over the n pose parameters, stacked last."""
    cols = []
    for c in range(n):
        d = np.zeros(n)
        d[c] = eps
        cols.append((f(d) - f(-d)) / (2 * eps))
    return np.stack(cols, axis=-1)


def test_subtree_matrix_marks_ancestors_or_self(template):
    sk = template.skeleton
    D = subtree_matrix(sk)
    foot, hip = sk.index("LeftFoot"), sk.index("LeftUpLeg")
    assert D[foot, hip] == 1 and D[hip, foot] == 0 and np.all(D[:, 0] == 1)
    assert np.array_equal(np.diag(D), np.ones(sk.n_joints))


def test_model_points_are_the_skinned_template_vertices(template, posed):
    model, R, root = posed
    v, n, _ = pose_points(model, R, root)
    full = template.pose(R, root).V
    assert np.abs(v - full[model.sample]).max() < 1e-12
    # blended-rotation normals agree with the posed mesh's normals almost everywhere
    cos = np.sum(n * vertex_normals(full, template.F)[model.sample], axis=1)
    assert np.median(cos) > 0.99 and np.mean(cos > 0.9) > 0.95


def test_point_jacobian_matches_finite_differences(template, posed):
    """∂v_i/∂(t, ω) from the subtree-accumulated lever arms, against central differences of
    the increment actually applied (float64, eps 1e-6): agreement to 1e-7 m/rad."""
    model, R, root = posed
    sk = template.skeleton
    n = 3 + 3 * sk.n_joints
    v, _, a = pose_points(model, R, root)
    m = len(v)
    analytic = np.zeros((m, 3, n))
    analytic[:, :, :3] = np.eye(3)
    for b in range(3):  # column (j, b): e_b × a_ij
        analytic[:, :, 3 + b :: 3] = np.cross(np.eye(3)[b], a).transpose(0, 2, 1)
    numeric = _numeric(
        lambda d: pose_points(model, *apply_increment(sk, R, root, d), jacobian=False)[0], n
    )
    assert np.abs(numeric - analytic).max() < 1e-7
    # the shortcut W_acc (v_i − p_j) is not exact for vertices blended across a subtree's
    # boundary: this test would catch it
    _, P = forward_kinematics(sk, R, root)
    shortcut = model.W_acc[:, :, None] * (v[:, None, :] - P[None])
    assert np.abs(shortcut - a).max() > 1e-3


@pytest.mark.parametrize("residual", ["point_to_plane", "point_to_point"])
def test_residual_jacobian_matches_finite_differences(template, posed, residual):
    model, R, root = posed
    sk = template.skeleton
    rng = np.random.default_rng(5)
    i = rng.integers(0, len(model.sample), 60)
    v, _, a = pose_points(model, R, root)
    y = v[i] + rng.normal(scale=0.02, size=(60, 3))
    ny = rng.normal(size=(60, 3))
    ny /= np.linalg.norm(ny, axis=1, keepdims=True)
    r, Jr = residual_jacobian(v, a, i, y, ny, residual)
    assert Jr.shape == (len(r), 3 + 3 * sk.n_joints)

    def res(d):
        vd, _, ad = pose_points(model, *apply_increment(sk, R, root, d))
        return residual_jacobian(vd, ad, i, y, ny, residual)[0]

    assert np.abs(_numeric(res, Jr.shape[1]) - Jr).max() < 1e-7


@pytest.fixture(scope="module")
def tracked(walk, template, tmp_path_factory):
    out = tmp_path_factory.mktemp("icp")
    opts = ICPOptions(max_iter=10)
    return (
        track_sequence(
            ArticulatedICP(opts), template, walk, out, truth_options(show_progress=False)
        ),
        out,
        opts,
    )


def testdata_to_model_pairs_searched_in_another_order_are_the_same(template):
    """The observed points searched in the frame's own order, with or without guesses: the
    pairs pykdtree's search in the sample's order gives, in that order."""
    from pykdtree.kdtree import KDTree

    from meshmocap.geometry.point_tree import point_tree

    rng = np.random.default_rng(2)
    v = template.V[rng.choice(template.n_vertices, 300, replace=False)]
    nv = vertex_normals(template.V, template.F)[: len(v)]
    pick = rng.choice(template.n_vertices, 1000, replace=False)
    Y = template.V[pick] + rng.normal(scale=0.01, size=(1000, 3))
    NY = vertex_normals(template.V, template.F)[pick]
    cand = dict(k=8, max_distance=0.1, normal_cos=0.3)
    queries, partner = nearest_compatible(KDTree(v), nv, Y, NY, **cand)
    want = np.full(len(Y), -1)
    want[queries] = partner
    perm = np.argsort(pick)
    order = (perm, np.ascontiguousarray(Y[perm]), NY[perm])
    assert 100 < len(queries) < 1000
    for hint in (None, want, rng.integers(-1, len(v), len(Y))):
        got = data_to_model(point_tree(v, nv), *order, hint=hint, **cand)
        assert np.array_equal(got, want)


def test_articulated_icp_follows_a_walk(walk, tracked, template):
    track, out, _ = tracked
    true = np.stack([f.truth.joints for f in walk])
    err = np.linalg.norm(track.joints - true, axis=2).mean(axis=1) * 1000  # mm per frame
    # measured (4-camera hulls, defaults, max_iter 10): 0, 5, 8, 8, 10, 10, 11, 10 mm; the
    # skeleton baseline follows the fat hull about as well as the patch tracker here
    assert err[0] < 1e-6
    assert err.max() < 20.0 and err[1:].mean() < 15.0
    assert track.healthy.all() and np.isfinite(track.vertices).all()
    assert set(track.energies) >= {"model_to_data", "data_to_model", "pose", "total"}
    assert np.all(track.n_iter[1:] >= 1) and np.all(track.n_iter <= 10)
    # joints not estimated keep their first-frame rotation
    last = read_state(out, int(track.frames[-1]))
    fixed = [template.skeleton.index(n) for n in FIXED_JOINTS]
    assert np.allclose(last["R"][fixed], walk[0].truth.rotations[fixed], atol=1e-12)


def test_interrupted_run_resumes_to_the_same_result(walk, tracked, template, tmp_path):
    track, out, opts = tracked
    part = tmp_path / "track"
    shutil.copytree(out, part)
    for i in (N_FRAMES - 2, N_FRAMES - 1):
        (part / "frames" / f"{i:05d}.npz").unlink()
    assert done_frames(part) == list(range(N_FRAMES - 2))
    again = track_sequence(
        ArticulatedICP(opts), template, walk, part, truth_options(show_progress=False)
    )
    assert np.allclose(again.joints, track.joints, atol=1e-9)  # seeded per frame: identical
    with pytest.raises(Exception, match="other settings"):
        track_sequence(
            ArticulatedICP(ICPOptions(max_iter=3)),
            template,
            walk,
            part,
            truth_options(show_progress=False),
        )


def test_point_cloud_frames_use_their_normals(walk, template):
    V, F = walk[1].hull_mesh
    cloud = SimpleNamespace(index=1, hull_mesh=(V, None), normals=vertex_normals(V, F))
    icp = ArticulatedICP(ICPOptions(max_iter=3))
    icp.init(template, walk[0], walk[0].truth.rotations, walk[0].truth.root)
    r = icp.step(cloud)
    assert np.isfinite(r.joints).all() and r.n_iter >= 1
    icp.init(template, walk[0], walk[0].truth.rotations, walk[0].truth.root)
    bare = icp.step(SimpleNamespace(index=1, hull_mesh=(V, None), normals=None))
    err = np.linalg.norm(bare.joints - r.joints, axis=1)  # normals estimated from the points
    assert err.max() < 0.02  # measured 8 mm


def test_the_registry_builds_it_with_options():
    icp = make_tracker("articulated_icp", max_iter=5)
    assert isinstance(icp, ArticulatedICP) and icp.options()["max_iter"] == 5
    assert icp.name == "articulated_icp"


def test_options_are_validated(template, walk):
    with pytest.raises(InputError, match="correspondences must be one of"):
        ICPOptions(correspondences="data_to_model")
    with pytest.raises(InputError, match="residual must be one of"):
        ICPOptions(residual="plane")
    with pytest.raises(InputError, match="max_distance"):
        ICPOptions(max_distance=0.0)
    with pytest.raises(InputError, match="n_model_points"):
        ICPOptions(n_model_points=0)
    with pytest.raises(InputError, match="lambda_pose"):
        ICPOptions(lambda_pose=-1.0)
    with pytest.raises(InputError, match="normal_cos"):
        ICPOptions(normal_cos=1.0)
    with pytest.raises(InputError, match="fixed_joints"):
        ICPOptions(fixed_joints="LHipJoint")
    with pytest.raises(InputError, match="extrapolate"):
        ICPOptions(extrapolate=0.5)
    with pytest.raises(InputError, match="settle_tol"):
        ICPOptions(settle_tol=-1e-3)
    with pytest.raises(InputError, match="options must be ICPOptions"):
        ArticulatedICP({"max_iter": 3})
    assert ICPOptions(fixed_joints=["Head"]).fixed_joints == ("Head",)
    with pytest.raises(InputError, match="expected R"):
        ArticulatedICP().init(template, walk[0], np.eye(3), np.zeros(3))


class _Failing(ArticulatedICP):
    """Cannot fit frame 3, as a frame with no usable observation would not be."""

    def step(self, frame):
        if frame.index == 3:
            raise FitError("no compatible correspondences")
        return super().step(frame)


def test_a_frame_that_cannot_be_fitted_raises_fit_error_and_the_driver_coasts(
    walk, template, tmp_path
):
    icp = ArticulatedICP(ICPOptions(max_iter=3))
    icp.init(template, walk[0], walk[0].truth.rotations, walk[0].truth.root)
    V, _ = walk[1].hull_mesh
    few = SimpleNamespace(index=1, hull_mesh=(V[:5], None), normals=np.tile([0, 0, 1.0], (5, 1)))
    with pytest.raises(FitError, match="only 5 observed points"):
        icp.step(few)
    track = track_sequence(
        _Failing(ICPOptions(max_iter=3)),
        template,
        walk,
        tmp_path / "t",
        truth_options(positions=range(5)),
    )
    assert track.healthy.tolist() == [True, True, True, False, True]
    assert track.messages[3] == "FitError: no compatible correspondences"
    assert np.array_equal(track.joints[3], track.joints[2])  # the last good result repeated


def test_held_it_continues_from_the_held_pose_with_its_velocity(walk, template):
    """On a 4D capture the driver holds the pose (estimate/pose/hold.py): the tracker takes
    the held pose as its own, its result that pose's skin, and keeps the pose before its
    last step for the next prediction."""
    icp = ArticulatedICP(ICPOptions(max_iter=2))
    icp.init(template, walk[0], walk[0].truth.rotations, walk[0].truth.root)
    icp.step(walk[1])
    before = icp.prev
    R, root = walk[1].truth.rotations, walk[1].truth.root
    r = icp.hold(walk[1], R, root)
    np.testing.assert_array_equal(icp.R, R)
    np.testing.assert_array_equal(icp.root, root)
    np.testing.assert_allclose(r.vertices, template.pose(R, root).V)
    assert icp.prev is before


def test_relaxation_goes_the_whole_way_along_a_geometric_series():
    """Steps shrinking by ρ each, taken whole: the next is taken 1 / (1 − ρ) times as long
    (the series' sum); taken at c, the next step is r = 1 − c (1 − ρ) times the one before
    and c / (1 − r) is again 1 / (1 − ρ); turning back, or none before, gives 1."""
    rng = np.random.default_rng(0)
    m = rng.normal(size=(50, 3))
    rho = 0.6
    c, last = relaxation(rho * m, m, 1.0, 10.0)
    assert c == pytest.approx(1 / (1 - rho)) and last is not m
    r = 1 - 2.0 * (1 - rho)  # the step before taken at 2
    assert relaxation(r * m, m, 2.0, 10.0)[0] == pytest.approx(1 / (1 - rho))
    assert relaxation(rho * m, m, 1.0, 1.5)[0] == 1.5  # at most `longest`
    assert relaxation(-0.5 * m, m, 1.0, 3.0)[0] == 1.0  # turned back: a whole step
    assert relaxation(m, None, 1.0, 3.0)[0] == 1.0
    assert relaxation(rho * m, m, 1.0, 1.0)[0] == 1.0  # off


def test_extrapolated_steps_end_near_the_plain_fit_in_fewer_iterations(walk, template):
    """Over-relaxed steps (and stopping where the steps turn back) take fewer iterations to
    a pose near the plain iteration's (its joints within 1 cm; measured 15 against 11
    iterations, 0.3–1.3 mm)."""
    fits = []
    for opts in (ICPOptions(extrapolate=1.0, settle_tol=0.0), ICPOptions()):
        icp = ArticulatedICP(opts)
        icp.init(template, walk[0], walk[0].truth.rotations, walk[0].truth.root)
        fits.append([icp.step(walk[i]) for i in (1, 2)])
    plain, fast = fits
    assert sum(r.n_iter for r in fast) < sum(r.n_iter for r in plain)
    for a, b in zip(plain, fast, strict=True):
        assert np.linalg.norm(a.joints - b.joints, axis=1).max() < 0.01
