"""The body shape and poses fitted to silhouettes (:mod:`meshmocap.estimate.performer.shape_fit`):
the shape Jacobian and the silhouette residuals' derivatives against finite differences,
and a fit from the mean body to the silhouettes of another recovering its surface."""

import numpy as np
import pytest

from meshmocap.body.articulated import apply_increment, articulated_model, pose_points
from meshmocap.body.shape_space import load_shape_space
from meshmocap.estimate.performer.shape_fit import (
    fit_shape,
    frame_terms,
    shape_jacobian,
    silhouette_view,
)
from meshmocap.geometry.rotations import so3_exp
from meshmocap.geometry.silhouette import silhouette
from meshmocap.studio.rigs import camera_rig


@pytest.fixture(scope="module")
def space():
    return load_shape_space()


def test_shape_jacobian_matches_finite_differences(space):
    rng = np.random.default_rng(1)
    z = 0.5 * rng.normal(size=16)
    R = so3_exp(0.3 * rng.normal(size=(31, 3)))
    root = np.array([0.1, 0.2, 0.9])
    S = shape_jacobian(space, space.template(z), R, root)
    eps = 1e-6
    for k in (0, 5, 15):
        dz = np.zeros(16)
        dz[k] = eps
        fd = space.template(z + dz).pose(R, root).V - space.template(z - dz).pose(R, root).V
        fd /= 2 * eps
        assert np.abs(fd - S[:, :, k]).max() < 1e-6 * max(1.0, np.abs(fd).max())


def test_silhouette_residual_derivatives_match_finite_differences(space):
    """Coverage and outline residuals (fixed correspondences) against central differences
    in a random direction of shape and pose. Both Jacobians hold the metres-per-pixel factor
    constant (coverage: median error 1 %); the outline's also takes the signed distance's
    slope from its interpolated gradient, not from the bilinear interpolant itself (median
    error 2-3 %)."""
    z = np.zeros(16)
    t = space.template(z)
    R = np.tile(np.eye(3), (31, 1, 1))
    root = t.skeleton.rest_positions[0] + np.array([0.0, 0.0, 0.0])
    cams = camera_rig("ring8")[:2]
    true = space.template(np.r_[-0.3, np.zeros(15)])  # a smaller body makes the silhouettes
    views = [silhouette_view(silhouette(true.V, true.F, c, assume_closed=True), c) for c in cams]

    def terms(z, R, root):
        t = space.template(z)
        v, n, a = pose_points(articulated_model(t, n_points=t.n_vertices), R, root)
        S = shape_jacobian(space, t, R, root)
        sample = articulated_model(t, n_points=500, seed=0).sample
        return {
            term: (r, Jp, Jz)
            for term, r, Jp, Jz in frame_terms(views, v, n, a, S, t.F, sample, 25.0).rows
        }

    base = terms(z, R, root)
    rng = np.random.default_rng(2)
    dp, dz, eps = 0.3 * rng.normal(size=96), rng.normal(size=16), 1e-6
    Rp, rp = apply_increment(t.skeleton, R, root, eps * dp)
    Rm, rm = apply_increment(t.skeleton, R, root, -eps * dp)
    plus, minus = terms(z + eps * dz, Rp, rp), terms(z - eps * dz, Rm, rm)
    for term, tol in (("outline", 0.05), ("coverage", 0.015)):
        r0, Jp, Jz = base[term]
        assert len(plus[term][0]) == len(r0) == len(minus[term][0]) > 50
        fd = (plus[term][0] - minus[term][0]) / (2 * eps)
        an = Jp @ dp + Jz @ dz
        assert np.median(np.abs(fd - an)) < tol * np.median(np.abs(an)), term


def test_a_fit_from_the_mean_body_recovers_another_body_from_its_silhouettes(space):
    """One frame, four cameras, a body 9 cm taller than the mean (z₀ = −0.3, z₁ = 0.2) in
    its rest pose; the fit starts from the mean body: 8 iterations bring the surface from
    62 mm to 5 mm (mean vertex distance, measured) and the height to within 1.5 mm."""
    true = space.template(np.r_[-0.3, 0.2, np.zeros(14)])
    views = [
        [silhouette_view(silhouette(true.V, true.F, c, assume_closed=True), c)]
        for c in camera_rig("humaneva4")
    ]
    views = [[v[0] for v in views]]  # one frame seen by the four cameras
    mean = space.template(np.zeros(16))
    R0 = np.tile(np.eye(3), (1, 31, 1, 1))
    root0 = mean.skeleton.rest_positions[:1].copy()
    fit = fit_shape(space, views, R0, root0, iterations=8, n_points=800)
    assert fit.z.shape == (16,) and fit.R.shape == (1, 31, 3, 3) and fit.root.shape == (1, 3)
    assert fit.n_iter == 8 and 0 < fit.rms < 0.01  # metres
    body = space.template(fit.z)
    V = body.pose(fit.R[0], fit.root[0]).V
    start = np.linalg.norm(mean.V - true.V, axis=1).mean()
    assert start > 0.05 and np.linalg.norm(V - true.V, axis=1).mean() < 0.01
    assert abs(np.ptp(body.V[:, 2]) - np.ptp(true.V[:, 2])) < 0.005


def test_outlines_rendered_in_their_box_and_terms_on_their_rows_are_the_whole_images(space):
    """The outline vertices found in the projected body's box equal those of the whole
    image's silhouette (the reference below), and the terms from the lever arms and shape
    Jacobians of the rows they use only equal those from every vertex's."""
    from pykdtree.kdtree import KDTree
    from scipy import ndimage

    from meshmocap.body.articulated import model_subset
    from meshmocap.estimate.performer.shape_fit import outlines

    rng = np.random.default_rng(5)
    z = 0.5 * rng.normal(size=16)
    t = space.template(z)
    R = so3_exp(0.2 * rng.normal(size=(31, 3)))
    root = t.skeleton.rest_positions[0] + np.array([0.3, -0.2, 0.0])
    model = articulated_model(t, n_points=t.n_vertices)
    v, n, a = pose_points(model, R, root)
    cams = camera_rig("humaneva4")
    views = [silhouette_view(silhouette(v, t.F, c, assume_closed=True), c) for c in cams]
    lines = outlines(views, v, n, t.F)
    for cam, got in zip(cams, lines, strict=True):
        mask = silhouette(v, t.F, cam, assume_closed=True)
        uv, depth = cam.project(v)
        view = (v - cam.centre) / np.linalg.norm(v - cam.centre, axis=1, keepdims=True)
        cand = np.flatnonzero((np.abs(np.sum(view * n, axis=1)) < 0.35) & (depth > 0))
        rows, cols = np.nonzero(mask & ~ndimage.binary_erosion(mask))
        d, k = KDTree(uv[cand]).query(
            np.stack([cols, rows], 1).astype(np.float64), k=1, distance_upper_bound=2.0
        )
        want = np.unique(cand[k[np.isfinite(d) & (k < len(cand))].astype(np.int64)])
        assert len(got) > 100 and np.array_equal(got, want)
    sample = articulated_model(t, n_points=500, seed=0).sample
    rows = np.unique(np.concatenate([sample, *lines]))
    S = shape_jacobian(space, t, R, root)
    S_rows = shape_jacobian(space, t, R, root, rows=rows)
    assert np.array_equal(S_rows, S[rows])
    _, _, a_rows = pose_points(model_subset(model, rows), R, root)
    whole = frame_terms(views, v, n, a, S, t.F, sample, 25.0).rows
    part = frame_terms(views, v, n, a_rows, S_rows, t.F, sample, 25.0, lines=lines, rows=rows)
    assert [r[0] for r in whole] == [r[0] for r in part.rows] and len(whole) >= 8
    for x, y in zip(whole, part.rows, strict=True):
        for u, w in zip(x[1:], y[1:], strict=True):
            assert np.array_equal(u, w)


@pytest.mark.slow
def test_a_frame_whose_pose_is_stuck_stops_informing_the_shape(space):
    """Two frames of one body (z₀ = −0.3, z₁ = 0.2), each started from the rest pose: the
    first is in it, the second has both arms raised, which the fit cannot reach (the arms
    are held at their starting rotations, as a pose settled in a wrong minimum is).
    Halfway, that frame's objective is many times the first's: it stops informing the
    shape, and the body comes out closer to the truth than when every frame informs it."""
    from meshmocap.body.articulated import FIXED_JOINTS

    true = space.template(np.r_[-0.3, 0.2, np.zeros(14)])
    names = space.joint_names
    R_up = np.tile(np.eye(3), (31, 1, 1))
    R_up[names.index("LeftArm")] = so3_exp(np.array([0.0, 1.5, 0.0]))
    R_up[names.index("RightArm")] = so3_exp(np.array([0.0, -1.5, 0.0]))
    rest_root = true.skeleton.rest_positions[0]
    cams = camera_rig("humaneva4")
    frames = []
    for R in (np.tile(np.eye(3), (31, 1, 1)), R_up):
        V = true.pose(R, rest_root).V
        frames.append(
            [silhouette_view(silhouette(V, true.F, c, assume_closed=True), c) for c in cams]
        )
    mean = space.template(np.zeros(16))
    R0 = np.tile(np.eye(3), (2, 31, 1, 1))
    root0 = np.tile(mean.skeleton.rest_positions[:1], (2, 1))
    held = (*FIXED_JOINTS, "LeftShoulder", "LeftArm", "RightShoulder", "RightArm")
    err = {}
    for ratio in (2.0, None):
        fit = fit_shape(
            space,
            frames,
            R0,
            root0,
            iterations=6,
            n_points=500,
            fixed_joints=held,
            screen_ratio=ratio,
        )
        err[ratio] = np.linalg.norm(space.template(fit.z).V - true.V, axis=1).mean()
        assert fit.shape_frames.tolist() == [True, ratio is None]
        assert fit.frame_cost[1] > 2 * fit.frame_cost[0]
    assert err[2.0] < 0.5 * err[None]


def test_fit_shape_rejects_a_screen_ratio_not_above_one(space):
    from meshmocap.errors import InputError

    with pytest.raises(InputError, match="screen_ratio must be > 1"):
        fit_shape(space, [[]], np.eye(3)[None, None], np.zeros((1, 3)), screen_ratio=0.5)
