"""Back-constrained GPLVM (cage paper §4–5): gradients, training, prediction, persistence."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import spearmanr
from threadpoolctl import threadpool_info, threadpool_limits

from meshmocap.apps.figures.latent import plot_latent_space
from meshmocap.errors import FormatError, InputError, MeshmocapFileNotFoundError
from meshmocap.models._kernels import rbf, sqdist
from meshmocap.models.gplvm import GPLVM, LatentProblem

# Central differences in float64 with h = 1e-6: truncation error O(h² f''') ≈ 1e-12 and
# rounding error ≈ eps |f| / h ≈ 1e-16 · 100 / 1e-6 = 1e-8 for the objectives below, so
# an absolute tolerance of 1e-6 (relative 1e-6 on large entries) has two orders to spare
# while a wrong factor or sign in any entry is O(1).
H = 1e-6
FD_TOL = {"rtol": 1e-6, "atol": 1e-6}


def central_fd(f, x: np.ndarray, h: float = H) -> np.ndarray:
    """Central finite-difference Jacobian of ``f`` at ``x`` (last axis: components of x)."""
    cols = [(np.asarray(f(x + e)) - np.asarray(f(x - e))) / (2 * h) for e in np.eye(x.size) * h]
    return np.stack(cols, axis=-1)


def curve(n: int = 60, d: int = 30, noise: float = 0.02, seed: int = 1):
    """Points on a smooth 1-D curve embedded in ``d`` dimensions, with Gaussian noise."""
    rng = np.random.default_rng(seed)
    t = np.sort(rng.uniform(0.0, 1.0, n))
    freq, phase = rng.uniform(0.3, 1.2, d), rng.uniform(0.0, 2 * np.pi, d)
    return t, np.sin(2 * np.pi * freq * t[:, None] + phase) + noise * rng.standard_normal((n, d))


@pytest.fixture(scope="module")
def curve_model():
    t, Y = curve()
    return t, Y, GPLVM(2).fit(Y)


# -- gradients -------------------------------------------------------------------------------
@pytest.mark.parametrize("bc", ["rbf", "mlp", None])
def test_log_likelihood_gradient_matches_finite_differences(bc):
    rng = np.random.default_rng(0)
    N, D, q, H_units = 12, 4, 2, 3
    Y = rng.standard_normal((N, D))
    Kbc = rbf(sqdist(Y), 1.0, 0.3) if bc == "rbf" else None
    prob = LatentProblem(Y, q, bc, Kbc=Kbc, n_hidden=H_units)
    n_w = D * H_units + H_units + H_units * q + q if bc == "mlp" else N * q
    # every parameter: log α, log γ, log β, then the back-constraint weights (or X)
    theta = np.concatenate([[0.2, -0.3, 1.5], 0.4 * rng.standard_normal(n_w)])
    f, g = prob(theta)
    assert np.isfinite(f) and g.shape == theta.shape
    np.testing.assert_allclose(g, central_fd(lambda th: prob(th)[0], theta), **FD_TOL)
    # the optimiser's coordinates (rbf: A = K_bc^(-1/2) B) chain correctly too
    phi = prob.from_model(theta)
    np.testing.assert_allclose(prob.to_model(phi), theta, rtol=1e-9, atol=1e-9)
    _, gphi = prob.in_optimiser_coords(phi)
    num = central_fd(lambda p: prob.in_optimiser_coords(p)[0], phi)
    np.testing.assert_allclose(gphi, num, **FD_TOL)


def test_objective_is_eq2():
    """The objective is -log Π_d N(Y[:, d] | 0, K): compare with scipy's density."""
    from scipy.stats import multivariate_normal

    rng = np.random.default_rng(1)
    Y, X = rng.standard_normal((8, 3)), rng.standard_normal((8, 2))
    prob = LatentProblem(Y, 2, None)
    f, _ = prob(np.concatenate([np.log([1.3, 0.7, 20.0]), X.ravel()]))
    K = rbf(sqdist(X), 1.3, 0.7) + np.eye(8) / 20.0
    ref = sum(multivariate_normal(np.zeros(8), K).logpdf(Y[:, d]) for d in range(3))
    assert f == pytest.approx(-ref, rel=1e-12)


@pytest.mark.parametrize("q", [2, 3])
def test_predictive_gradients_match_finite_differences(q):
    _, Y = curve(n=25, d=6)
    model = GPLVM(q, max_iter=60).fit(Y)
    rng = np.random.default_rng(2)
    for x in [model.X_[4] + 0.3 * rng.standard_normal(q), model.X_.mean(0)]:
        mean, dmean, var, dvar = model.predict_with_gradient(x)
        assert mean.shape == (6,) and dmean.shape == (6, q) and dvar.shape == (q,)
        num = central_fd(lambda z: model.predict_with_gradient(z)[0], x)
        np.testing.assert_allclose(dmean, num, **FD_TOL)  # Eq. (8)
        # σ² = α - k_xᵀK⁻¹k_x cancels: its rounding error is ≈ eps·α·β·N ≈ 1e-10 here
        # (β ≈ 3e3), which h = 1e-6 would turn into 5e-5; h = 1e-3 gives rounding 5e-8 and
        # truncation h²/6·|σ²'''| ≈ 1e-7 (latent length-scale ~1), inside the 1e-6 tolerance.
        num = central_fd(lambda z: model.predict_with_gradient(z)[2], x, h=1e-3)
        np.testing.assert_allclose(dvar, num, **FD_TOL)  # Eq. (10)
        # the hot path agrees with the batch predictor (same formulas, different order)
        m2, v2 = model.predict(x[None], return_var=True)
        np.testing.assert_allclose(mean, m2[0], rtol=1e-12, atol=1e-12)
        assert var == pytest.approx(v2[0], abs=1e-9)  # cancellation: ≈ eps·α·β·N, above


# -- training --------------------------------------------------------------------------------
def test_fit_increases_likelihood_and_sets_attributes(curve_model):
    _, Y, m = curve_model
    h = m.log_likelihood_history_
    assert h.shape == (m.n_iter_ + 1,)
    # L-BFGS-B accepts a step only on sufficient decrease of the objective
    assert np.all(np.diff(h) >= 0)
    assert h[-1] > h[0] + 100
    assert m.log_likelihood_ == pytest.approx(h[-1], rel=1e-12)
    assert m.converged_
    N, D = Y.shape
    assert m.X_.shape == (N, 2) and m.A_.shape == (N, 2) and m.mlp_weights_ is None
    assert m.Kinv_.shape == (N, N) and m.Y_mean_.shape == (D,) and m.Y_scale_ > 0
    assert min(m.alpha_, m.gamma_, m.beta_) > 0
    # the back-constraint holds: X = K_bc(Y, Y) A, and transform maps the training poses there
    np.testing.assert_allclose(m.transform(Y), m.X_, rtol=1e-10, atol=1e-10)


def test_latent_space_follows_a_one_dimensional_curve(curve_model):
    t, Y, m = curve_model
    # ordering: the first latent coordinate is monotonic in the curve parameter
    assert abs(spearmanr(m.X_[:, 0], t)[0]) > 0.99
    # local distances preserved: each point's latent nearest neighbour is ≤ 2 steps away
    d = sqdist(m.X_)
    np.fill_diagonal(d, np.inf)
    assert np.max(np.abs(np.argmin(d, 1) - np.arange(len(t)))) <= 2
    # the mean reconstructs the training poses to about the noise level (0.02)
    mean, var_train = m.predict(m.X_, return_var=True)
    assert np.sqrt(np.mean((mean - Y) ** 2)) < 0.03
    # variance: small at the data, grows away from it towards k(x, x) = α (data units)
    prior = m.alpha_ * m.Y_scale_**2
    assert var_train.max() < 0.01 * prior
    direction = np.array([1.0, 1.0]) / np.sqrt(2)
    ell = 1 / np.sqrt(m.gamma_)
    start = m.X_[np.argmax(m.X_ @ direction)]
    rays = start + np.outer(np.linspace(0.5, 6, 12) * ell, direction)
    _, var_ray = m.predict(rays, return_var=True)
    assert np.all(np.diff(var_ray) > 0)
    assert var_ray[-1] > 0.9 * prior


@pytest.mark.parametrize("bc", ["mlp", None])
def test_other_back_constraints_fit(bc):
    t, Y = curve(n=40)
    m = GPLVM(2, back_constraint=bc, random_state=3).fit(Y)
    assert np.all(np.diff(m.log_likelihood_history_) >= 0)
    assert abs(spearmanr(m.X_[:, 0], t)[0]) > 0.98
    if bc == "mlp":
        np.testing.assert_allclose(m.transform(Y), m.X_, rtol=1e-10, atol=1e-10)
        assert m.A_ is None and len(m.mlp_weights_) == 4
    else:
        with pytest.raises(InputError, match="back-constraint"):
            m.transform(Y)


def test_deterministic_with_random_state():
    _, Y = curve(n=30, d=8)
    a = GPLVM(2, back_constraint="mlp", random_state=7, max_iter=40).fit(Y)
    b = GPLVM(2, back_constraint="mlp", random_state=7, max_iter=40).fit(Y)
    c = GPLVM(2, back_constraint="mlp", random_state=8, max_iter=40).fit(Y)
    np.testing.assert_array_equal(a.X_, b.X_)
    assert a.log_likelihood_ == b.log_likelihood_
    assert not np.array_equal(a.X_, c.X_)
    r1, r2 = GPLVM(2, max_iter=40).fit(Y), GPLVM(2, max_iter=40).fit(Y)
    np.testing.assert_array_equal(r1.X_, r2.X_)


def test_fit_from_an_earlier_fit_starts_where_it_ended(curve_model, tmp_path):
    _, Y, m = curve_model
    # the earlier fit's latent points and kernel: the back-constraint's least squares
    # reaches its X to the ridge, so the new fit starts at its likelihood, not PCA's
    warm = GPLVM(2, alpha=m.alpha_, gamma=m.gamma_, beta=m.beta_, init=m.X_, max_iter=30)
    warm.fit(Y)
    h = warm.log_likelihood_history_
    assert h[0] == pytest.approx(m.log_likelihood_, abs=1e-3 * abs(m.log_likelihood_))
    assert h[0] > m.log_likelihood_history_[0] + 100 and np.all(np.diff(h) >= 0)
    assert GPLVM.load(warm.save(tmp_path / "w.npz")).init is None  # not part of the model
    with pytest.raises(InputError, match=r"init must have shape \(60, 2\)"):
        GPLVM(2, init=m.X_[:10]).fit(Y)


def test_the_likelihood_reads_the_poses_only_through_their_rank():
    # Eq. (2) reads Y through Y Yᵀ: poses of rank 3 in 6 columns give the likelihood and
    # gradient of their 3-column factor, to rounding
    rng = np.random.default_rng(5)
    Y = rng.standard_normal((10, 3)) @ rng.standard_normal((3, 6))
    theta = np.concatenate([[0.1, -0.2, 1.0], 0.5 * rng.standard_normal(20)])
    low = LatentProblem(Y, 2, None)
    assert low.F.shape == (10, 3)
    f, g = low(theta)
    full = LatentProblem(Y, 2, None)
    full.F = Y
    f2, g2 = full(theta)
    assert f == pytest.approx(f2, rel=1e-12)
    np.testing.assert_allclose(g, g2, rtol=1e-9, atol=1e-9)


def test_fit_runs_on_one_blas_thread_whatever_the_callers(monkeypatch):
    # other thread counts sum in another order: over hundreds of L-BFGS-B iterations the
    # last bits carry the fit to another optimum, so the fit pins one thread itself
    import meshmocap.models.gplvm as gplvm_module

    def blas():
        return [p["num_threads"] for p in threadpool_info() if p["user_api"] == "blas"]

    seen = []
    real = gplvm_module.minimize

    def spy(*args, **kwargs):
        seen.append(blas())
        return real(*args, **kwargs)

    monkeypatch.setattr(gplvm_module, "minimize", spy)
    _, Y = curve(n=30, d=8)
    with threadpool_limits(2):
        before = blas()
        GPLVM(2, max_iter=5).fit(Y)
        after = blas()
    assert seen and seen[0] and all(n == 1 for n in seen[0])
    assert after == before  # the caller's setting is back


# -- contract, validation, persistence ---------------------------------------------------------
def test_unfitted_model_raises_and_has_no_fitted_attributes():
    m = GPLVM(3, back_constraint="mlp", tol=1e-5)
    assert set(vars(m)) == set(m.get_params())  # __init__ only stores options
    assert not hasattr(m, "X_") and not hasattr(m, "alpha_")
    for call in (
        lambda: m.predict(np.zeros((1, 3))),
        lambda: m.predict_with_gradient(np.zeros(3)),
        lambda: m.transform(np.zeros((1, 5))),
        lambda: m.save("x.npz"),
    ):
        with pytest.raises(InputError, match="not fitted"):
            call()


def test_invalid_options_and_inputs(curve_model):
    _, Y, m = curve_model
    with pytest.raises(InputError, match=r"back_constraint must be one of \['rbf', 'mlp'\]"):
        GPLVM(back_constraint="kernel").fit(Y)
    with pytest.raises(InputError, match="n_components"):
        GPLVM(0).fit(Y)
    with pytest.raises(InputError, match="beta"):
        GPLVM(beta=-1.0).fit(Y)
    bad = Y.copy()
    bad[0, 0] = np.nan
    with pytest.raises(InputError, match="finite"):
        GPLVM().fit(bad)
    with pytest.raises(InputError, match="no variance"):
        GPLVM().fit(np.ones((10, 3)))
    with pytest.raises(InputError, match=r"shape \(n, 2\)"):
        m.predict(np.zeros((4, 3)))
    with pytest.raises(InputError, match=r"shape \(2,\)"):
        m.predict_with_gradient(np.zeros(3))
    with pytest.raises(InputError, match=r"shape \(n, 30\)"):
        m.transform(np.zeros((2, 29)))


def test_save_load_round_trip_is_exact(tmp_path, curve_model):
    _, Y, m = curve_model
    path = m.save(tmp_path / "pose_manifold.npz")
    assert [p.name for p in tmp_path.iterdir()] == ["pose_manifold.npz"]  # no temp left over
    m2 = GPLVM.load(path)
    assert m2.get_params() == m.get_params()
    for name in (
        "alpha_",
        "gamma_",
        "beta_",
        "Y_scale_",
        "n_iter_",
        "converged_",
        "log_likelihood_",
        "bc_gamma_",
    ):
        assert getattr(m2, name) == getattr(m, name)
    rng = np.random.default_rng(4)
    Xq = m.X_[:5] + 0.2 * rng.standard_normal((5, 2))
    for a, b in zip(m.predict(Xq, return_var=True), m2.predict(Xq, return_var=True), strict=True):
        np.testing.assert_array_equal(a, b)
    for a, b in zip(m.predict_with_gradient(Xq[0]), m2.predict_with_gradient(Xq[0]), strict=True):
        np.testing.assert_array_equal(a, b)
    np.testing.assert_array_equal(m.transform(Y[:7]), m2.transform(Y[:7]))


def test_load_rejects_bad_files(tmp_path, curve_model):
    with pytest.raises(MeshmocapFileNotFoundError):
        GPLVM.load(tmp_path / "missing.npz")
    (tmp_path / "junk.npz").write_bytes(b"not a zip")
    with pytest.raises(FormatError):
        GPLVM.load(tmp_path / "junk.npz")
    path = curve_model[2].save(tmp_path / "m.npz")
    with np.load(path) as z:
        d = dict(z)
    d["format_version"] = np.array(99)
    np.savez(tmp_path / "future.npz", **d)
    with pytest.raises(FormatError, match="version 99"):
        GPLVM.load(tmp_path / "future.npz")


def test_plot_latent_space(tmp_path, curve_model):
    _, Y, m = curve_model
    out = plot_latent_space(m, tmp_path / "latent.png", resolution=40)
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    m3 = GPLVM(3, max_iter=30).fit(Y)  # q > 2: the principal plane of the latent points
    labels = (np.arange(len(Y)) > 30).astype(int)
    assert plot_latent_space(m3, tmp_path / "latent3.svg", resolution=20, labels=labels).is_file()
    m1 = GPLVM(1, max_iter=30).fit(Y)
    assert plot_latent_space(m1, tmp_path / "latent1.png", resolution=20).is_file()
    with pytest.raises(InputError, match="must end in"):
        plot_latent_space(m, tmp_path / "latent.txt")
    with pytest.raises(InputError, match="fitted GPLVM"):
        plot_latent_space(GPLVM(), tmp_path / "x.png")


# -- real data ---------------------------------------------------------------------------------
# cmu35WalkJog.mat (Lawrence's CMU subject 35 set): the 31 columns of ``lbls`` are the trials
# in increasing id order; walks are 35_01–16, 28, 30–34 and jogs 35_17, 19–26.
TRIALS = [*range(1, 17), 17, *range(19, 27), 28, *range(30, 35)]
JOGS = {17, *range(19, 27)}


def test_walks_and_jogs_separate_in_latent_space(shared_data):
    from scipy.io import loadmat

    path = shared_data / "mocap" / "cmu" / "cmu35WalkJog.mat"
    if not path.is_file():
        pytest.skip(f"{path} is absent")
    mat = loadmat(path)
    Y = mat["Y"][:, 3:]  # raw AMC channels without the root translation (tx, ty, tz)
    trial = np.array(TRIALS)[np.argmax(mat["lbls"], 1)]
    jog = np.isin(trial, list(JOGS))
    # 60 walk and 60 jog frames, evenly spread over each class (rows 0:480 are all walks)
    walk_rows, jog_rows = np.flatnonzero(~jog), np.flatnonzero(jog)
    pick = [r[np.linspace(0, len(r) - 1, 60).astype(int)] for r in (walk_rows, jog_rows)]
    rows = np.concatenate(pick)
    m = GPLVM(2).fit(Y[rows])
    assert np.all(np.diff(m.log_likelihood_history_) >= 0)
    d = sqdist(m.X_)
    np.fill_diagonal(d, np.inf)  # leave-one-out 1-NN classifier on the latent points
    accuracy = np.mean(jog[rows][np.argmin(d, 1)] == jog[rows])
    assert accuracy > 0.9
