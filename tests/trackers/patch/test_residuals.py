"""The patch tracker's extensions (issue 20): silhouette coverage and the temporal prior —
pixels and rays, gradients against float64 finite differences, and their effect."""

import numpy as np
import pytest

from meshmocap.body.template import load_template
from meshmocap.geometry.camera import Camera, intrinsics, look_at
from meshmocap.geometry.coverage import mask_samples, pixel_rays, uncovered
from meshmocap.geometry.rotations import so3_exp
from meshmocap.trackers.patch.model import build_patch_model
from meshmocap.trackers.patch.residuals import add_joint_prior, add_silhouette, silhouette_rays
from meshmocap.trackers.patch.solver import System, normal_pattern

RNG = np.random.default_rng(3)


def _camera(dist=None) -> Camera:
    R, t = look_at(np.array([0.0, -3.0, 1.0]), np.array([0.0, 0.0, 1.0]))
    return Camera(intrinsics(160, 120, 60.0), R, t, 160, 120, dist=dist)


@pytest.mark.parametrize("dist", [None, np.array([-0.2, 0.05, 0.001, -0.002, 0.0])])
def test_pixel_rays_pass_through_their_pixels(dist):
    """A point on the ray of pixel uv projects back to uv (to 1e-6 px, distortion
    included: the inverse is a fixed-point iteration)."""
    cam = _camera(dist)
    uv = RNG.uniform([10, 10], [150, 110], size=(50, 2))
    o, d = pixel_rays(cam, uv)
    assert np.allclose(np.linalg.norm(d, axis=1), 1.0)
    back, depth = cam.project(o + 2.5 * d)
    assert np.all(depth > 0) and np.abs(back - uv).max() < 1e-6


def test_mask_samples_and_uncovered_pixels():
    """A disc of surface points covers the disc's pixels; pixels of a larger silhouette
    beyond it are uncovered, with their gap measured in metres at the points' depth."""
    cam = _camera()
    mask = np.zeros((120, 160), bool)
    mask[40:80, 60:100] = True  # silhouette: a square
    uv = mask_samples(mask, 2)
    assert len(uv) == 20 * 20 and mask[uv[:, 1].astype(int), uv[:, 0].astype(int)].all()
    # points on a dense grid filling the left half of the square, at 3 m
    o, d = pixel_rays(cam, uv[uv[:, 0] < 80])
    X = o + 3.0 * d / d[:, [1]]  # on the plane y = 0
    f = cam.K[0, 0]
    radius = 2.5 * 3.0 / f  # 2.5 px at 3 m (the grid spacing is 2 px)
    pix, j, gap = uncovered(cam, uv, X, radius=radius)
    assert set(pix) == set(np.flatnonzero(uv[:, 0] >= 82))  # 80 is 2 px from a point: covered
    right = uv[pix, 0]
    assert np.allclose(gap, (right - 78) * 3.0 / f, rtol=1e-6)  # nearest point: column 78
    assert np.all(X[j, 0] > X[:, 0].max() - 1e-9)  # pulled points are on the right edge


@pytest.fixture(scope="module")
def patch_setup():
    t = load_template("neutral_5k")
    m = build_patch_model(t, n_patches=60, seed=1)
    R = so3_exp(RNG.normal(scale=0.2, size=(m.P, 3)))
    c = m.centres0 + RNG.normal(scale=0.02, size=(m.P, 3))
    return t, m, R, c


def _vertices(m, R, c):
    return np.einsum("nij,nj->ni", R[m.labels], m.V0 - m.centres0[m.labels]) + c[m.labels]


def test_silhouette_gradient_matches_finite_differences(patch_setup):
    """The coverage term's gradient against central differences of Σ w |P⊥(v − o)|² with
    its pixels, vertices and weights held (float64, h = 1e-6)."""
    _, m, R, c = patch_setup
    cam = _camera()
    V = _vertices(m, R, c)
    # a silhouette wider than the body's projection: its outer pixels are uncovered
    uvb, _ = cam.project(V)
    mask = np.zeros(cam.shape, bool)
    lo, hi = np.floor(uvb.min(0)).astype(int) - 6, np.ceil(uvb.max(0)).astype(int) + 6
    mask[max(lo[1], 0) : hi[1], max(lo[0], 0) : hi[0]] = True
    rays = silhouette_rays([cam], [mask])
    q = np.einsum("nij,nj->ni", R[m.labels], m.V0 - m.centres0[m.labels])
    sys = System.empty(normal_pattern(m, 15))
    radius, scale = 0.02, 0.05
    e, share = add_silhouette(sys, rays, V, m.labels, q, radius=radius, scale=scale, weight=1.0)
    pix, j, gap = uncovered(cam, rays.uv[0], V, radius=radius)
    keep = gap < 0.3
    pix, j, gap = pix[keep], j[keep], gap[keep]
    w = 1 / (1 + (gap / scale) ** 2)
    assert 0 < share < 1 and len(pix) > 20
    o, d = rays.origin[0], rays.dirs[0][pix]

    def energy(R, c):
        v = _vertices(m, R, c)[j] - o
        r = v - d * np.sum(v * d, axis=1, keepdims=True)
        return np.sum(w * np.sum(r * r, axis=1)) / rays.n

    assert e == pytest.approx(energy(R, c), rel=1e-12)
    h = 1e-6
    touched = np.unique(m.labels[j])
    for k in RNG.choice(touched, 8, replace=False):
        for a in range(6):
            i = 6 * k + a
            dl = np.zeros(6 * m.P)
            dl[i] = h
            dd = dl.reshape(m.P, 6)
            fp = energy(so3_exp(dd[:, :3]) @ R, c + dd[:, 3:])
            fm = energy(so3_exp(-dd[:, :3]) @ R, c - dd[:, 3:])
            assert (fp - fm) / (2 * h) == pytest.approx(2 * sys.g[i], rel=1e-5, abs=1e-9), i


def test_joint_prior_gradient_and_step(patch_setup):
    """The temporal prior: value, gradient against finite differences, and one
    Gauss–Newton step of it alone puts every joint on its prediction."""
    t, m, _, _ = patch_setup
    X = t.eval_skeleton.rest_positions.copy()
    X_hat = X + RNG.normal(scale=0.05, size=X.shape)
    sys = System.empty(normal_pattern(m, 15))
    value = add_joint_prior(sys, X, X_hat, 2.0)
    assert value == pytest.approx(np.sum((X - X_hat) ** 2), rel=1e-12)
    g = sys.g[6 * m.P :]
    h = 1e-6
    for i in range(45):
        d = np.zeros(45)
        d[i] = h
        ep = 2.0 * np.sum((X + d.reshape(15, 3) - X_hat) ** 2)
        em = 2.0 * np.sum((X - d.reshape(15, 3) - X_hat) ** 2)
        assert (ep - em) / (2 * h) == pytest.approx(2 * g[i], rel=1e-6, abs=1e-10)
    step = sys.solve(0.0)[6 * m.P :].reshape(15, 3)
    assert np.abs(X + step - X_hat).max() < 2e-3 * np.abs(X - X_hat).max()


def test_bench_ablation_table_reports_each_change_against_patch():
    """One row per ablation present, one column per capture with a ``patch`` row; each
    cell is the ablation's mean and its change against ``patch``; another tracker's
    ablations against that tracker."""
    from meshmocap.apps.bench.report import ablation_table
    from meshmocap.apps.bench.rows import BenchRow, not_applicable

    rows = [
        BenchRow("walk", "patch", mean_mm=10.0),
        BenchRow("walk", "patch_sil", mean_mm=12.5),
        BenchRow("jog", "patch", mean_mm=20.0),
        BenchRow("jog", "patch_paper", mean_mm=19.0),
        BenchRow("crane", "articulated_icp", mean_mm=30.0),
        not_applicable("jog", "patch_sil", "no silhouettes"),
    ]
    table = ablation_table(rows).splitlines()
    assert table[0] == "| method | change | walk | jog |"
    assert table[2] == "| patch | — | 10.0 | 20.0 |"
    assert table[3] == "| patch_sil | + silhouette coverage | 12.5 (+2.5) |  |"
    assert table[4] == "| patch_paper | − every extension (the paper alone) |  | 19.0 (-1.0) |"
    assert ablation_table(rows[:1]) == ""
    rows.append(BenchRow("crane", "patch", mean_mm=20.0))
    other = ablation_table(rows, "articulated_icp", {"patch": "the patch tracker"})
    assert other.splitlines()[3] == "| patch | the patch tracker | 20.0 (-10.0) |"


def test_hull_points_deep_inside_the_model_fall_to_the_outlier_class():
    """``interior_scale``: points 5 cm behind the model surface (a silhouette hole's tunnel
    through the hull) keep under 10 % of their E-step weight, points on it all of theirs;
    without the option both keep most of it."""
    from types import SimpleNamespace

    from pykdtree.kdtree import KDTree

    from meshmocap.trackers.patch.tracker import PatchOptions, PatchTracker

    t = load_template("neutral_5k")
    R = np.broadcast_to(np.eye(3), (t.skeleton.n_joints, 3, 3)).copy()
    weights = {}
    for scale in (0.0, 0.01):
        tr = PatchTracker(
            PatchOptions(n_patches=60, interior_scale=scale, joint_readout="skeleton")
        )
        tr.init(t, SimpleNamespace(index=0), R, np.zeros(3))
        Vc, Nc = tr.own_vertices()
        inside = Vc - 0.05 * Nc
        depth, _ = KDTree(Vc).query(inside, k=1)  # 5 cm deep: in the torso, not a thin limb
        deep = np.flatnonzero(depth > 0.045)
        on, ins = RNG.choice(len(Vc), 200, replace=False), RNG.choice(deep, 200, replace=False)
        Y, NY = np.vstack([Vc[on] + 0.002 * Nc[on], inside[ins]]), np.vstack([Nc[on], Nc[ins]])
        tr.sigma = 0.03
        k = tr.correspondences(Y, NY, None, Vc, Nc)
        w, y = k.weight, k.point
        is_in = np.isin(y, inside[ins]).all(axis=1)
        weights[scale] = (w[~is_in].sum() / 200, w[is_in].sum() / 200)
    assert weights[0.0][0] > 0.95 and weights[0.0][1] > 0.5
    assert weights[0.01][0] > 0.95 and weights[0.01][1] < 0.1


def test_acceleration_gate_stops_extrapolating_a_velocity_that_just_jumped():
    """``accel_gate`` (m/s²): the whole body starting to move at 3 cm a frame from rest
    (1.8 m/s at 60 fps: 108 m/s² > 72) is not extrapolated; at 30 fps (27 m/s²) or with
    the gate off it is, each patch carried along."""
    from types import SimpleNamespace

    from meshmocap.trackers.patch.tracker import PatchOptions, PatchTracker

    t = load_template("neutral_5k")
    R = np.broadcast_to(np.eye(3), (t.skeleton.n_joints, 3, 3)).copy()
    step = np.array([0.03, 0.0, 0.0])
    for gate, fps, moved in ((72.0, 60.0, False), (72.0, 30.0, True), (0.0, 60.0, True)):
        tr = PatchTracker(PatchOptions(n_patches=60, accel_gate=gate, joint_readout="skeleton"))
        tr.init(t, SimpleNamespace(index=0), R, np.zeros(3))
        X0, c0 = tr.X.copy(), tr.c.copy()
        tr.X, tr.c = X0 + step, c0 + step  # the last frame moved 3 cm, the one before not
        tr._predict_by_bones(fps)
        expect = 2 * step if moved else step
        assert np.abs(tr.X - X0 - expect).max() < 1e-9
        assert np.abs(tr.c - c0 - expect).max() < 1e-9


def test_bench_says_where_patch_loses_to_its_baseline():
    """The report names each capture where ``patch`` has a larger mean than articulated
    ICP, with both means and worst frames; nothing where it wins."""
    from meshmocap.apps.bench.report import baseline_losses
    from meshmocap.apps.bench.rows import BenchRow

    rows = [
        BenchRow("walk", "patch", mean_mm=10.0, worst_frame_mm=20.0),
        BenchRow("walk", "articulated_icp", mean_mm=12.0, worst_frame_mm=25.0),
        BenchRow("jog", "patch", mean_mm=22.0, worst_frame_mm=60.0),
        BenchRow("jog", "articulated_icp", mean_mm=18.0, worst_frame_mm=30.5),
    ]
    assert baseline_losses(rows) == (
        "**`patch` is worse than `articulated_icp` on:** `jog` "
        "(22.0 against 18.0 mm, worst frame 60.0 against 30.5)."
    )
    assert baseline_losses(rows[:2]) == ""
