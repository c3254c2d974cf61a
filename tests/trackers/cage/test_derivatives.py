"""The cage tracker's analytic gradients against float64 central differences.

Each Levenberg–Marquardt problem of :class:`CageTracker` (pose, Eq. 11; latent shape,
Eqs. 5–6; local adjustment, Eq. 12) returns its energy and, from ``linearise``, the
gradient; both are checked along random directions on a smooth analytic field (a distance
grid has kinks between cells, which would blur finite differences).
"""

import numpy as np
import pytest

from meshmocap.body.procedural import walk
from meshmocap.body.template import load_template
from meshmocap.geometry.rotations import so3_exp
from meshmocap.models.gplvm import GPLVM
from meshmocap.trackers.cage.oqr import build_oqr, configuration_vector, quads_from_pose
from meshmocap.trackers.cage.quad_frames import pose_jacobian
from meshmocap.trackers.cage.residuals import HullCoverage, SilhouetteCoverage
from meshmocap.trackers.cage.surface import GreenSurface, SkinnedSurface
from meshmocap.trackers.cage.terms import FrameData, Iterate
from meshmocap.trackers.cage.tracker import CageOptions, CageTracker, orthonormalised


class _Field:
    """A smooth signed 'distance' around a point, with an exact gradient."""

    def __init__(self, centre: np.ndarray) -> None:
        self.c = centre

    def value_and_gradient(self, P):
        d = P - self.c
        r = np.linalg.norm(d, axis=1)
        wave = 0.1 * np.sin(5 * P[:, 0])
        grad = d / r[:, None]
        grad[:, 0] += 0.5 * np.cos(5 * P[:, 0])
        return r - 0.3 + wave, grad


@pytest.fixture(scope="module", params=["skinned", "green"])
def tracker(request):
    t = load_template("neutral_5k")
    oqr = build_oqr(t)
    m = walk(t, duration=1.0, fps=30.0)
    Y = configuration_vector(*quads_from_pose(oqr, t, m.rotations, m.root_positions))
    # Poses with 2 cm of noise: a well-conditioned GP. On exactly low-dimensional poses K is
    # near singular and σ²(x) carries ~1e-3 relative rounding noise, which would swamp the
    # finite differences of log σ² (the analytic gradient is not the culprit).
    Y = Y + 0.02 * np.random.default_rng(0).normal(size=Y.shape)
    gp = GPLVM(2, max_iter=200, random_state=0).fit(Y)
    opts = CageOptions(n_sample=60, variance_weight=1e-3, surface=request.param)
    tr = CageTracker(gp, opts)
    tr.setup(t)
    if request.param == "skinned":  # only the vertices with exact derivatives (class notes)
        tr.sample = tr.sample[tr.surface.exact]
        tr.surface = SkinnedSurface(tr.oqr, t, tr.sample)
        assert len(tr.sample) >= 20 and tr.surface.exact.all()
    tr.pelvis_R, tr.pelvis_c = m.rotations[0][0], m.root_positions[0]
    tr.x = gp.X_[:2].mean(axis=0) + 0.3
    tr.local = gp.predict(tr.x[None])[0]
    return tr, _Field(tr.pelvis_c + np.array([0.05, -0.02, 0.1]))


def _check(problem, state, dim, seed, h=1e-6):
    evaluate, linearise, update = problem
    _, cache = evaluate(state)
    g, H = linearise(state, cache)
    assert H.shape == (dim, dim) and np.all(np.linalg.eigvalsh(H) > -1e-12)  # Gauss–Newton
    rng = np.random.default_rng(seed)
    for _ in range(3):
        d = rng.normal(size=dim)
        fd = (evaluate(update(state, h * d))[0] - evaluate(update(state, -h * d))[0]) / (2 * h)
        # central differences: O(h²) truncation, ~1e-16 |E| / h rounding
        assert abs(g @ d - fd) <= 1e-6 * max(1.0, abs(fd)), (g @ d, fd)


def _silhouette(tr):
    """A silhouette term of one camera 3 m in front of the pelvis, its mask a disc larger
    than the body's image: contour pixels far from every projected model point."""
    from meshmocap.geometry.camera import Camera

    K = np.array([[500.0, 0, 160], [0, 500.0, 120], [0, 0, 1]])
    R = np.array([[1.0, 0, 0], [0, 0, -1], [0, 1, 0]])  # looks along +Y, image y down
    t = -R @ (tr.pelvis_c - np.array([0.0, 3.0, 0.0]))
    rr, cc = np.mgrid[:240, :320]
    mask = (rr - 120) ** 2 + (cc - 160) ** 2 < 110**2
    return SilhouetteCoverage([Camera(K, R, t, 320, 240)], [mask], 60, 1.0, seed=0)


def _frame(tr, field, hull=None, silhouettes=None):
    """What the tracker's terms read in a frame: the data term (Eq. 4) on ``field``, and a
    hull or silhouette coverage term where given."""
    return FrameData(
        field=field,
        point_weights=tr._data_w,
        noise=tr.gp.Y_scale_**2 / tr.gp.beta_,
        articulation=tr._articulation,
        hull=hull,
        silhouettes=silhouettes,
    )


@pytest.fixture(params=["data", "coverage", "silhouette"])
def terms(request, tracker):
    """The data term alone, or with a hull coverage term (samples on a sphere around the
    pelvis, 25 of them farther than the margin from every model point; some model points
    are left out of the data term, as the first frame's misplaced ones), or with a
    silhouette term."""
    tr, field = tracker
    keep = np.ones(len(tr.sample), dtype=bool)
    P = tr.surface.points(tr.local, tr.pelvis_R, tr.pelvis_c)
    extra: dict = {}
    if request.param == "coverage":
        rng = np.random.default_rng(7)
        H = rng.normal(size=(40, 3))
        H = tr.pelvis_c + 0.6 * H / np.linalg.norm(H, axis=1, keepdims=True)
        term = HullCoverage(H, margin=0.05)
        keep[::3] = False
        assert (term.residuals(P)[0] > 0).sum() >= 5
        extra = {"hull": term}
    elif request.param == "silhouette":
        term = _silhouette(tr)
        assert (term.residuals(P)[0] > 0).sum() >= 5
        extra = {"silhouettes": term}
    tr._set_keep(keep)
    yield tr, _frame(tr, field, **extra)
    tr._set_keep(np.ones(len(tr.sample), dtype=bool))


def test_pose_gradient(terms):
    tr, fd = terms
    _check(tr._pose_problem(fd, tr.local), (tr.pelvis_R, tr.pelvis_c), 6, seed=1)


def test_latent_shape_gradient_with_the_variance_term(terms):
    tr, fd = terms
    _check(tr._shape_problem(fd), tr.x, tr.x.size, seed=2, h=1e-5)


@pytest.mark.parametrize("anchored", [False, True])
def test_local_adjustment_gradient(terms, anchored):
    tr, fd = terms
    rng = np.random.default_rng(3)
    y = orthonormalised(tr.local + 0.02 * rng.normal(size=tr.local.size))
    anchor = orthonormalised(y + 0.05 * rng.normal(size=y.size)) if anchored else None
    _check(tr._local_problem(fd, anchor), (y, tr.pelvis_R, tr.pelvis_c), 126, seed=4)


def test_pose_jacobian_is_the_rigid_motion_of_the_points(tracker):
    tr, field = tracker
    fd = _frame(tr, field)
    data = tr.terms[0]  # the distance term (Eq. 4)
    P = tr.surface.points(tr.local, tr.pelvis_R, tr.pelvis_c)
    _, g = data.residuals(Iterate(fd, P))
    J = pose_jacobian(P, g, tr.pelvis_c)
    rng = np.random.default_rng(5)
    d, h = rng.normal(size=6), 1e-6

    def moved(s):
        R = so3_exp(s * d[:3])
        return data.residuals(Iterate(fd, (P - tr.pelvis_c) @ R.T + tr.pelvis_c + s * d[3:]))[0]

    np.testing.assert_allclose(J.T @ d, (moved(h) - moved(-h)) / (2 * h), rtol=0, atol=1e-7)


def _walk_configuration():
    """The light body's quads, template, 300 sampled vertices and configuration ``y``
    (with the pelvis's ``Rp``, ``cp``) at the third frame of a short walk."""
    t = load_template("neutral_5k")
    oqr = build_oqr(t)
    m = walk(t, duration=0.5, fps=10.0)
    c, Q = quads_from_pose(oqr, t, m.rotations[2:3], m.root_positions[2:3])
    y = configuration_vector(c, Q)[0]
    Rp, cp = Q[0, 0], c[0, 0]
    sample = np.random.default_rng(0).choice(len(t.V), 300, replace=False)
    return oqr, t, sample, y, Rp, cp


@pytest.mark.parametrize("surface", [SkinnedSurface, GreenSurface])
def test_surface_directions_against_central_differences(surface):
    """``directions`` along random configuration directions: exact (1e-7 m) for the
    vertices :attr:`SkinnedSurface.exact` marks (all of the Green surface's), within 25 %
    for the skinned vertices of quad-less joints (the Gauss–Newton approximation)."""
    oqr, t, sample, y, Rp, cp = _walk_configuration()
    s = surface(oqr, t, sample)
    rng = np.random.default_rng(1)
    dy = rng.normal(size=(180, 2)) * 0.01
    D = s.directions(y, Rp, cp, dy)
    h = 1e-6
    for k in range(2):
        fd = (s.points(y + h * dy[:, k], Rp, cp) - s.points(y - h * dy[:, k], Rp, cp)) / (2 * h)
        ex = getattr(s, "exact", np.ones(len(sample), dtype=bool))
        np.testing.assert_allclose(D[k][ex], fd[ex], rtol=0, atol=1e-7)
        if not ex.all():
            err = np.linalg.norm(D[k][~ex] - fd[~ex]) / np.linalg.norm(fd[~ex])
            assert err < 0.25, err


def test_local_normal_equations_equal_the_dense_products():
    """The compiled ``Jᵀ r`` and ``Jᵀ J`` of the local adjustment (a few quads per point row)
    equal the dense products of :meth:`SkinnedSurface.quad_rows` and ``pose_jacobian``'s
    rows to rounding, on every sampled vertex (quad-less joints included)."""
    oqr, t, sample, y, Rp, cp = _walk_configuration()
    s = SkinnedSurface(oqr, t, sample)
    rng = np.random.default_rng(2)
    P = s.points(y, Rp, cp)
    G = rng.normal(size=(2, len(sample), 3))
    r = rng.normal(size=2 * len(sample))
    pelvis = pose_jacobian(np.tile(P, (2, 1)), G.reshape(-1, 3), cp)
    J = np.concatenate([s.quad_rows(y, Rp, cp, G), pelvis])
    g, H = s.local_normal_equations(y, Rp, cp, G, P, r)
    np.testing.assert_allclose(g, J @ r, rtol=0, atol=1e-12 * np.abs(J @ r).max())
    np.testing.assert_allclose(H, J @ J.T, rtol=0, atol=1e-12 * np.abs(J @ J.T).max())
