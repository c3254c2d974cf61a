"""The residuals of the cage tracker's terms: the energy's vertex sample, the hull coverage
residuals and the soft joints (trackers/cage/residuals.py)."""

import numpy as np
import pytest

from meshmocap.body.template import load_template
from meshmocap.errors import InputError
from meshmocap.trackers.cage.residuals import (
    HullCoverage,
    SilhouetteCoverage,
    placement_errors,
    surface_sample,
)


def test_surface_sample_follows_the_area():
    t = load_template("neutral_5k")
    idx = surface_sample(t.V, t.F, 800, seed=0)
    assert len(idx) == 800 and np.all(np.diff(idx) > 0)  # sorted, no repeats
    assert np.array_equal(idx, surface_sample(t.V, t.F, 800, seed=0))  # seeded
    A = 0.5 * np.linalg.norm(
        np.cross(t.V[t.F[:, 1]] - t.V[t.F[:, 0]], t.V[t.F[:, 2]] - t.V[t.F[:, 0]]), axis=1
    )
    area = np.bincount(t.F.ravel(), np.repeat(A, 3), minlength=t.n_vertices) / 3
    head = np.asarray(t.weights.argmax(axis=1)).ravel() == t.skeleton.index("Head")
    share = head[idx].mean()
    # the head holds a quarter of the vertices but ~8 % of the area; 800 draws without
    # replacement: binomial standard deviation ~1 %, so 3 % covers it
    assert head.mean() > 0.2 and abs(share - area[head].sum() / area.sum()) < 0.03
    few = surface_sample(t.V[:10], np.array([[0, 1, 2]]), 50, seed=1)  # 7 isolated vertices
    assert np.array_equal(few, np.arange(10))  # at most every vertex
    with pytest.raises(InputError, match="n must be"):
        surface_sample(t.V, t.F, 0, seed=0)


def test_placement_errors_are_distances():
    a, b = np.zeros((2, 3)), np.array([[3.0, 4.0, 0.0], [0.0, 0.0, -2.0]])
    np.testing.assert_array_equal(placement_errors(a, b), [5.0, 2.0])


def test_coverage_energy_and_gradient_match_brute_force_and_finite_differences():
    rng = np.random.default_rng(0)
    H, P = rng.normal(size=(300, 3)), rng.normal(size=(40, 3))
    cov = HullCoverage(H, margin=0.1)

    def energy(P):
        d = np.linalg.norm(H[:, None] - P[None], axis=2).min(axis=1)
        return 0.5 * np.sum(np.maximum(d - 0.1, 0.0) ** 2)

    r, a = cov.residuals(P)
    assert len(cov) == 300 and r.shape == (40,) and a.shape == (40, 3)
    assert abs(0.5 * r @ r - energy(P)) <= 1e-12 * energy(P)
    h, grad = 1e-6, r[:, None] * a
    for _ in range(3):
        d = rng.normal(size=P.shape)
        fd = (energy(P + h * d) - energy(P - h * d)) / (2 * h)
        # central differences: O(h²) truncation; no sample changes its nearest point
        assert abs(np.sum(grad * d) - fd) <= 1e-6 * max(1.0, abs(fd))
    far = HullCoverage(H, margin=10.0).residuals(P)  # everything covered
    assert not far[0].any() and not far[1].any()
    with pytest.raises(InputError, match="margin"):
        HullCoverage(H, margin=-1.0)
    with pytest.raises(InputError, match="points"):
        HullCoverage(H[:, :2], margin=0.0)


def test_articulation_gaps_jacobian_and_calibration():
    from meshmocap.body.procedural import walk
    from meshmocap.geometry.rotations import so3_exp
    from meshmocap.trackers.cage.oqr import (
        QUAD_NAMES,
        build_oqr,
        configuration_from_vector,
        configuration_vector,
        quads_from_pose,
    )
    from meshmocap.trackers.cage.residuals import Articulation

    t = load_template("neutral_5k")
    oqr, sk = build_oqr(t), t.skeleton
    q = oqr.quads
    art = Articulation(q.centres, q.rotations, q.joint_indices, sk.rest_positions, sk.parents)
    assert [QUAD_NAMES[i] for i in art.parent[:3]] == ["pelvis", "abdomen", "chest"]
    assert art.rigid.sum() == 2  # wrist and hand quads follow the same joint

    def relative(R_local, root):
        y = configuration_vector(*quads_from_pose(oqr, t, R_local, root))
        return configuration_from_vector(y)

    rest = np.tile(np.eye(3), (sk.n_joints, 1, 1))
    e, J = art.residuals(*relative(rest, sk.rest_positions[0]), jacobian=True)
    assert J.shape == (len(e), 120) and np.abs(e).max() < 1e-12  # closed at rest
    m = walk(t, duration=1.0, fps=10.0)
    c, R = relative(m.rotations, m.root_positions)
    gaps = art.calibrate(c, R, 0.005)
    # the procedural walk bends Spine1 (before the neck and shoulders) and the clavicles:
    # those pairs open, every pair of consecutive joints stays closed
    open_ = {QUAD_NAMES[i] for i in art.child[gaps > 1e-3]}
    assert open_ <= {"neck", "head", "left_shoulder", "right_shoulder"} and "neck" in open_
    assert np.all(art.weights[gaps < 1e-9] == 1.0) and np.all(art.weights[gaps > 1e-3] < 0.99)
    rng = np.random.default_rng(4)
    c0, R0 = c[3], R[3]
    e, J = art.residuals(c0, R0, jacobian=True)
    h = 1e-6
    for _ in range(3):
        d = rng.normal(size=(20, 6))

        def moved(s, d=d):
            c1, R1 = c0.copy(), R0.copy()
            c1[1:] += s * d[:, :3]
            R1[1:] = so3_exp(s * d[:, 3:]) @ R0[1:]
            return art.residuals(c1, R1)

        fd = (moved(h) - moved(-h)) / (2 * h)
        # central differences: O(h²) truncation and ~1e-16/h rounding on O(1) values
        np.testing.assert_allclose(J @ d.ravel(), fd, rtol=0, atol=1e-8)


def test_graft_hangs_the_donor_limb_on_the_trunk():
    from meshmocap.trackers.cage.oqr import QUAD_NAMES, configuration_from_vector
    from meshmocap.trackers.cage.quad_frames import graft, orthonormalised

    rng = np.random.default_rng(6)
    y, donor = (orthonormalised(rng.normal(size=180)) for _ in range(2))
    arm = np.array([QUAD_NAMES.index(f"left_{q}") for q in ("shoulder", "elbow", "wrist")])
    chest = QUAD_NAMES.index("chest")
    leg = graft(y, donor, 0, arm)  # from the pelvis: the donor's quads as they are
    c, R = configuration_from_vector(leg)
    cd, Rd = configuration_from_vector(donor)
    np.testing.assert_allclose(c[arm], cd[arm], rtol=0, atol=1e-15)
    out = np.setdiff1d(np.arange(1, 21), arm)
    np.testing.assert_array_equal(leg.reshape(-1, 3, 3)[out - 1], y.reshape(-1, 3, 3)[out - 1])
    g = graft(y, donor, chest, arm)  # from the chest: the same pose relative to y's chest
    c, R = configuration_from_vector(g)
    cy, Ry = configuration_from_vector(y)
    np.testing.assert_allclose(R[chest], Ry[chest], rtol=0, atol=1e-12)  # the trunk stays
    np.testing.assert_allclose(c[chest], cy[chest], rtol=0, atol=1e-15)
    rel = np.swapaxes(R[chest], 0, 1) @ R[arm]
    reld = np.swapaxes(Rd[chest], 0, 1) @ Rd[arm]
    np.testing.assert_allclose(rel, reld, rtol=0, atol=1e-12)
    off = (c[arm] - c[chest]) @ R[chest]
    offd = (cd[arm] - cd[chest]) @ Rd[chest]
    np.testing.assert_allclose(off, offd, rtol=0, atol=1e-12)


def test_silhouette_coverage_prices_unexplained_contour_and_caps_blobs():
    """A body's image whose contour every projected model point explains costs nothing; a
    blob 60 px away costs its distance beyond the margin (in metres at the points' depth),
    unless the cap makes it an outlier or cleaning drops it."""
    from meshmocap.geometry.camera import Camera

    K = np.array([[500.0, 0, 160], [0, 500.0, 120], [0, 0, 1]])
    cam = Camera(K, np.eye(3), np.zeros(3), 320, 240)  # looks along +Z
    rng = np.random.default_rng(0)
    # model points filling a 0.4 m square at 2 m: the 100 px square around the centre
    P = np.column_stack([rng.uniform(-0.2, 0.2, (4000, 2)), np.full(4000, 2.0)])
    rr, cc = np.mgrid[:240, :320]
    body = (np.abs(rr - 120) < 49) & (np.abs(cc - 160) < 49)
    blob = (rr - 120) ** 2 + (cc - 270) ** 2 < 8**2  # 60 px right of the square's edge
    clean = SilhouetteCoverage([cam], [body], 400, 4.0, seed=0)
    assert np.all(clean.residuals(P)[0] == 0)
    noisy = SilhouetteCoverage([cam], [body | blob], 400, 4.0, seed=0)
    r = noisy.residuals(P)[0]
    # the blob's contour lies 52-68 px from the nearest point, 0.004 m a pixel at 2 m
    per = r[r > 0] ** 2  # each point's share: Σ ρ² of the samples nearest to it
    assert per.sum() > 0 and np.sqrt(per.max()) >= (52 - 4) * 0.004
    capped = SilhouetteCoverage([cam], [body | blob], 400, 4.0, seed=0, cap=15.0)
    assert np.all(capped.residuals(P)[0] == 0)
    # or the blob, 2 % of the body's area, is cleaned off the mask (kept at 1 %)
    cleaned = SilhouetteCoverage([cam], [body | blob], 400, 4.0, seed=0, min_component=0.03)
    assert np.all(cleaned.residuals(P)[0] == 0)
    kept = SilhouetteCoverage([cam], [body | blob], 400, 4.0, seed=0, min_component=0.01)
    assert np.any(kept.residuals(P)[0] > 0)
