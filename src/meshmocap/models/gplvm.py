"""Back-constrained Gaussian-process latent variable model: the cage tracker's pose manifold.

Cage paper §4–5 (Duveau et al. 2012), after Lawrence (2005) and Lawrence & Quiñonero-Candela
(2006, "Local distance preservation in the GP-LVM through back constraints").

Model. The N training poses Y (N, D) are centred by their column means and divided by one
global scale (the root of the mean column variance, so every channel keeps its relative
weight and the predictive variance stays one number per latent point). Each standardised
column is a draw of one Gaussian process over the latent points X (N, q), Eq. (2)::

    log p(Y | X, θ) = -D/2 log|K| - 1/2 tr(K⁻¹ Y Yᵀ) - N D/2 log 2π,
    K = K_rbf(X, X; α, γ) + β⁻¹ I.

The paper writes the product of Eq. (2) over ``y_i`` with covariance K (N, N); this only
makes sense over the D columns (Lawrence's formulation), which is what is implemented. The
paper's θ holds α and γ only; the white-noise precision β of Lawrence's kernel is learned as
well (without it K is singular at coincident latent points and the likelihood unbounded).

Back-constraint. The latent points are not free but a function of the data, so that poses
close in data space stay close in latent space:

* ``"rbf"``: X = K_bc(Y, Y) A, with K_bc an RBF of fixed inverse width ``bc_gamma`` on the
  standardised data (default 1 / median squared pairwise distance) and A (N, q) learned;
* ``"mlp"``: X = tanh(Y W₁ + b₁) W₂ + b₂ with ``n_hidden`` tanh units;
* ``None``: X itself is optimised (the plain GPLVM).

K_bc (N, N) has full rank, so in exact arithmetic every X is reachable through A: as in
Lawrence & Quiñonero-Candela the ``"rbf"`` constraint acts through the smooth PCA start and
the optimiser's path (it finds other optima than the free GPLVM); ``"mlp"`` with fewer
hidden units than N is a hard constraint.

Training maximises Eq. (2) over log α, log γ, log β and the back-constraint weights with
L-BFGS-B on closed-form gradients; the latent points are initialised by PCA (scaled so the
first principal coordinate has unit variance), or at given points (``init``: an earlier fit
on poses of the same motions). Eq. (2) reads Y only through Y Yᵀ, so the likelihood is
evaluated on a factor of Y Yᵀ with as many columns as Y's rank (pose sets of fewer
independent directions than columns: fewer products a step). For ``"rbf"`` the optimiser
works on B = K_bc^(1/2) A (X = K_bc^(1/2) B), the same model in better-conditioned coordinates:
3–5x fewer iterations than on A and higher likelihoods on the CMU walk/jog data.

Prediction (latent point x → pose), in the original data units::

    μ(x)  = Y_mean + s Yᵀ K⁻¹ k_x                 Eq. (7)
    dμ/dx = s Yᵀ K⁻¹ dk_x/dx                      Eq. (8)
    σ²(x) = s² (k(x, x) - k_xᵀ K⁻¹ k_x)           Eq. (9)
    dσ²/dx = s² (dk(x, x)/dx - 2 k_xᵀ K⁻¹ dk_x/dx) Eq. (10), dk(x, x)/dx = 0 for the RBF,

with s = ``Y_scale_``, k(x, x) = α (the noise-free latent function's variance; the noise
β⁻¹ is not added) and dk_x/dx = γ (X - x) ⊙ k_x from Eq. (3).

References
----------
- E. Duveau, S. Courtemanche, L. Reveret, E. Boyer, *Cage-based motion recovery
  using manifold learning*, International Conference on 3D Imaging, Modeling,
  Processing, Visualization and Transmission (3DIMPVT), 2012.
- N. D. Lawrence, *Probabilistic non-linear principal component analysis with
  Gaussian process latent variable models*, Journal of Machine Learning Research
  6:1783–1816, 2005.
- N. D. Lawrence, J. Quiñonero-Candela, *Local distance preservation in the GP-LVM
  through back constraints*, International Conference on Machine Learning (ICML),
  2006. https://doi.org/10.1145/1143844.1143909
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Literal, get_args

import numpy as np
from scipy.optimize import minimize
from threadpoolctl import threadpool_limits

from meshmocap._atomic import atomic_open
from meshmocap._npz import read_npz
from meshmocap._tolerances import NORM_FLOOR
from meshmocap._validate import check_choice
from meshmocap.errors import FormatError, InputError, MeshmocapFileNotFoundError
from meshmocap.models._kernels import chol_inverse, rbf, sqdist

#: Eigenvalues of the back-constraint kernel clipped at this fraction of the largest (a
#: singular kernel: duplicated rows).
_EIGENVALUE_CLIP = 1e-10
#: Singular values of the standardised poses below this fraction of the largest are
#: rounding noise (a pose set of lower rank than its width): left out of the likelihood's
#: factor of Y Yᵀ (:class:`LatentProblem`).
_RANK_CLIP = 1e-10
#: Ridge of the back-constraint's first least-squares weights (a near-singular kernel).
_BACK_RIDGE = 1e-6

BackConstraint = Literal["rbf", "mlp"]
_BC_CHOICES = (*get_args(BackConstraint), None)
FORMAT_VERSION = 1
_KIND = "meshmocap.GPLVM"
_LOG2PI = float(np.log(2.0 * np.pi))
# Bounds of log α, log γ, log β: keep K positive definite (noise variance ≥ e⁻¹⁴ ≈ 8e-7
# of the unit data variance) and the RBF away from under/overflow.
_HYPER_BOUNDS = [(-14.0, 14.0), (-18.0, 18.0), (-7.0, 14.0)]


class LatentProblem:
    """The negative log-likelihood of Eq. (2) as a function of one flat parameter vector.

    Parameter layout: ``[log α, log γ, log β, back-constraint weights...]`` where the weights
    are ``A`` (N, q) for ``"rbf"``, ``W1 (D, H), b1 (H,), W2 (H, q), b2 (q,)`` for ``"mlp"``
    and the latent points X (N, q) for ``None``; arrays are flattened in C order.
    """

    def __init__(self, Ys: np.ndarray, q: int, bc: str | None, *, Kbc=None, n_hidden=0, svd=None):
        self.Y, self.q, self.bc, self.Kbc, self.H = Ys, q, bc, Kbc, n_hidden
        self.N, self.D = Ys.shape
        # Eq. (2) reads Y only through Y Yᵀ: a factor F with F Fᵀ = Y Yᵀ and no more columns
        # than Y's rank (its singular vectors times their values, the null directions left
        # out) gives the same likelihood and gradient with fewer columns to multiply; ``svd``:
        # ``np.linalg.svd(Ys, full_matrices=False)`` where the caller has it already
        U, sv, _ = np.linalg.svd(Ys, full_matrices=False) if svd is None else svd
        rank = int(np.sum(sv > _RANK_CLIP * sv[0])) if sv.size and sv[0] > 0 else 0
        self.F = np.ascontiguousarray(U[:, :rank] * sv[:rank]) if rank < self.D else Ys
        N, D, H = self.N, self.D, n_hidden
        sizes = {"rbf": [N * q], "mlp": [D * H, H, H * q, q], None: [N * q]}[bc]
        self.splits = np.cumsum([3, *sizes])[:-1]
        self.upper = np.triu(np.ones((N, N), dtype=bool), 1)
        self.T = self.Tinv = None
        if bc == "rbf":
            # Optimiser coordinates B = K_bc^(1/2) A (so X = K_bc^(1/2) B): the same model,
            # but the curvature in B scales with the eigenvalues of K_bc instead of their
            # squares, which cuts L-BFGS-B iterations by 3-5x (eigenvalues clipped at 1e-10
            # of the largest where K_bc is singular, e.g. duplicated rows).
            s, U = np.linalg.eigh(Kbc)
            s = np.maximum(s, _EIGENVALUE_CLIP * s[-1])
            self.T = (U * s**-0.5) @ U.T  # A = T B
            self.Tinv = (U * s**0.5) @ U.T

    def unpack(self, theta: np.ndarray) -> tuple[float, float, float, list[np.ndarray]]:
        """``(α, γ, β, back-constraint weights)`` of the flat parameters ``theta`` (the
        class docstring's layout; the hyperparameters exponentiated)."""
        parts = np.split(theta, self.splits)
        alpha, gamma, beta = np.exp(parts[0])
        if self.bc == "mlp":
            D, H, q = self.D, self.H, self.q
            w = [parts[1].reshape(D, H), parts[2], parts[3].reshape(H, q), parts[4]]
        else:
            w = [parts[1].reshape(self.N, self.q)]
        return float(alpha), float(gamma), float(beta), w

    def latent(self, w: list[np.ndarray]) -> tuple[np.ndarray, object]:
        """Latent points X (N, q) and the hidden layer (mlp) for back-propagation."""
        if self.bc == "rbf":
            return self.Kbc @ w[0], None  # X = K_bc(Y, Y) A
        if self.bc == "mlp":
            W1, b1, W2, b2 = w
            Hd = np.tanh(self.Y @ W1 + b1)
            return Hd @ W2 + b2, Hd
        return w[0], None

    def back(self, dX: np.ndarray, w: list[np.ndarray], cache) -> list[np.ndarray]:
        """Chain rule: dL/dX (N, q) → dL/d(back-constraint weights)."""
        if self.bc == "rbf":
            return [self.Kbc.T @ dX]  # dX/dA: X = K_bc A
        if self.bc == "mlp":
            Hd, W2 = cache, w[2]
            dZ = (dX @ W2.T) * (1.0 - Hd * Hd)  # tanh' = 1 - tanh²
            return [self.Y.T @ dZ, dZ.sum(0), Hd.T @ dX, dX.sum(0)]
        return [dX]

    def __call__(self, theta: np.ndarray) -> tuple[float, np.ndarray]:
        """Negative log-likelihood (Eq. (2)) and its gradient w.r.t. ``theta``."""
        alpha, gamma, beta, w = self.unpack(theta)
        X, cache = self.latent(w)
        N, D = self.N, self.D
        d2 = sqdist(X)
        Kf = rbf(d2, alpha, gamma)  # Eq. (3)
        K = Kf.copy()
        K.flat[:: N + 1] += 1.0 / beta  # K = K_rbf + β⁻¹ I
        try:
            Kinv, logdet = chol_inverse(K, self.upper)
        except np.linalg.LinAlgError:
            return np.inf, np.zeros_like(theta)
        KinvF = Kinv @ self.F
        # Eq. (2), product over the D columns of Y (tr(K⁻¹ Y Yᵀ) = tr(K⁻¹ F Fᵀ))
        ll = -0.5 * D * logdet - 0.5 * float(np.sum(self.F * KinvF)) - 0.5 * N * D * _LOG2PI
        G = 0.5 * (KinvF @ KinvF.T - D * Kinv)  # dL/dK (symmetric)
        GK = G * Kf
        g_alpha = float(GK.sum())  # dK/dlog α = K_rbf
        g_gamma = float(-0.5 * gamma * np.sum(GK * d2))  # dK/dlog γ = -γ/2 d² K_rbf
        g_beta = float(-np.trace(G) / beta)  # dK/dlog β = -β⁻¹ I
        dX = -2.0 * gamma * (GK.sum(1)[:, None] * X - GK @ X)  # dK_ij/dx_i = -γ(x_i-x_j)K_ij
        gw = self.back(dX, w, cache)
        grad = np.concatenate([[g_alpha, g_gamma, g_beta], *[g.ravel() for g in gw]])
        return -ll, -grad

    def to_model(self, phi: np.ndarray) -> np.ndarray:
        """Optimiser coordinates → model parameters (``A = T B`` for ``"rbf"``)."""
        if self.T is None:
            return phi
        return np.concatenate([phi[:3], (self.T @ phi[3:].reshape(self.N, self.q)).ravel()])

    def from_model(self, theta: np.ndarray) -> np.ndarray:
        """Model parameters → optimiser coordinates."""
        if self.T is None:
            return theta
        B = self.Tinv @ theta[3:].reshape(self.N, self.q)
        return np.concatenate([theta[:3], B.ravel()])

    def in_optimiser_coords(self, phi: np.ndarray) -> tuple[float, np.ndarray]:
        """Objective and gradient in optimiser coordinates (chain rule through ``A = T B``)."""
        f, g = self(self.to_model(phi))
        if self.T is not None:
            g[3:] = (self.T.T @ g[3:].reshape(self.N, self.q)).ravel()
        return f, g


def _check_rows(func: str, name: str, Y: object, width: int | None) -> np.ndarray:
    Y = np.asarray(Y, dtype=np.float64)
    if Y.ndim != 2 or (width is not None and Y.shape[1] != width):
        want = f"(n, {width})" if width is not None else "(n, d)"
        raise InputError(f"{func}: {name} must have shape {want}, found {Y.shape}")
    if not np.all(np.isfinite(Y)):
        raise InputError(f"{func}: {name} must be finite, found NaN or inf")
    return Y


class GPLVM:
    """Back-constrained GPLVM with the RBF kernel of Eq. (3) (scikit-learn contract).

    Parameters
    ----------
    n_components : int
        Latent dimension q ≥ 1.
    back_constraint : {"rbf", "mlp", None}
        How the latent points depend on the data (module docstring).
    alpha, gamma, beta : float
        Initial RBF variance α, inverse width γ (in the PCA-initialised latent units) and
        noise precision β (in standardised data units); all three are learned.
    bc_gamma : float or None
        Fixed inverse width of the ``"rbf"`` back-constraint kernel on the standardised
        data; None: 1 / median squared pairwise distance of the training poses.
    n_hidden : int
        Hidden tanh units of the ``"mlp"`` back-constraint.
    max_iter : int
        Maximum L-BFGS-B iterations.
    tol : float
        L-BFGS-B stopping tolerance: relative reduction of the objective (``ftol``); the
        projected gradient tolerance is ``tol`` times the number of data entries.
    random_state : int, numpy.random.Generator or None
        Seeds the random initial weights of the ``"mlp"`` back-constraint (the other
        variants are deterministic).
    init : (N, q) array_like of float or None
        Latent points to start from (reached through the back-constraint as the PCA
        start is: least squares), e.g. those of an earlier fit on poses of the same
        motions (with its ``alpha``, ``gamma``, ``beta``); None: the scaled PCA
        coordinates. Not saved with the model (:meth:`save`).

    Attributes
    ----------
    X_ : (N, q) float64
        Latent points of the training poses.
    alpha_, gamma_, beta_ : float
        Learned RBF variance, inverse width and noise precision.
    A_ : (N, q) float64 or None
        ``"rbf"`` back-constraint weights (``X_ = K_bc(Y_, Y_) A_``); None otherwise.
    mlp_weights_ : tuple of arrays or None
        ``"mlp"`` weights ``(W1 (D, H), b1 (H,), W2 (H, q), b2 (q,))``; None otherwise.
    bc_gamma_ : float
        Inverse width of the ``"rbf"`` back-constraint kernel (nan otherwise).
    Y_ : (N, D) float64
        Standardised training poses, ``(Y - Y_mean_) / Y_scale_``.
    Y_mean_ : (D,) float64
        Column means of the training poses.
    Y_scale_ : float
        Global scale of the training poses.
    Kinv_ : (N, N) float64
        K⁻¹ with ``K = K_rbf(X_, X_) + β⁻¹ I``.
    KinvY_ : (N, D) float64
        ``K⁻¹ Y_`` (standardised units).
    n_iter_ : int
        L-BFGS-B iterations run.
    log_likelihood_ : float
        Eq. (2) at the optimum, on the standardised data.
    log_likelihood_history_ : (``n_iter_`` + 1,) float64
        Eq. (2) at the start and after every iteration (non-decreasing).
    converged_ : bool
        Whether L-BFGS-B met its tolerance before ``max_iter``.
    """

    def __init__(
        self,
        n_components: int = 2,
        *,
        back_constraint: BackConstraint | None = "rbf",
        alpha: float = 1.0,
        gamma: float = 1.0,
        beta: float = 100.0,
        bc_gamma: float | None = None,
        n_hidden: int = 20,
        max_iter: int = 2000,
        tol: float = 1e-7,
        random_state: int | np.random.Generator | None = None,
        init: np.ndarray | None = None,
    ) -> None:
        self.n_components = n_components
        self.back_constraint = back_constraint
        self.alpha = alpha
        self.gamma = gamma
        self.beta = beta
        self.bc_gamma = bc_gamma
        self.n_hidden = n_hidden
        self.max_iter = max_iter
        self.tol = tol
        self.random_state = random_state
        self.init = init

    # -- scikit-learn plumbing ------------------------------------------------------------
    _PARAMS = (
        "n_components",
        "back_constraint",
        "alpha",
        "gamma",
        "beta",
        "bc_gamma",
        "n_hidden",
        "max_iter",
        "tol",
        "random_state",
        "init",
    )

    def get_params(self, deep: bool = True) -> dict:
        """The constructor options, as a dict."""
        return {k: getattr(self, k) for k in self._PARAMS}

    def set_params(self, **params) -> GPLVM:
        """Set constructor options; returns self."""
        for k, v in params.items():
            if k not in self._PARAMS:
                raise InputError(f"GPLVM.set_params: unknown option {k!r}")
            setattr(self, k, v)
        return self

    def __repr__(self) -> str:
        return f"GPLVM(n_components={self.n_components}, back_constraint={self.back_constraint!r})"

    def _check_options(self, N: int, D: int) -> None:
        if self.back_constraint is not None:
            check_choice("GPLVM", "back_constraint", self.back_constraint, _BC_CHOICES[:-1])
        q = self.n_components
        if not isinstance(q, int | np.integer) or not 1 <= q <= min(D, N - 2):
            raise InputError(
                f"GPLVM: n_components must be an int in [1, {min(D, N - 2)}] "
                f"for data of shape ({N}, {D}), found {q!r}"
            )
        for name in ("alpha", "gamma", "beta", "tol"):
            v = getattr(self, name)
            if not (np.isscalar(v) and np.isfinite(v) and v > 0):
                raise InputError(f"GPLVM: {name} must be a positive float, found {v!r}")
        if self.bc_gamma is not None and not (np.isfinite(self.bc_gamma) and self.bc_gamma > 0):
            raise InputError(f"GPLVM: bc_gamma must be positive or None, found {self.bc_gamma!r}")
        for name in ("n_hidden", "max_iter"):
            v = getattr(self, name)
            if not isinstance(v, int | np.integer) or v < 1:
                raise InputError(f"GPLVM: {name} must be a positive int, found {v!r}")

    # -- training ---------------------------------------------------------------------------
    def fit(self, Y: np.ndarray, y: None = None) -> GPLVM:
        """Learn the latent points, kernel hyper-parameters and back-constraint from poses.

        Parameters
        ----------
        Y : (N, D) array_like of float
            Training poses, one per row (N ≥ q + 2).
        y : None
            Ignored (scikit-learn signature).

        Returns
        -------
        GPLVM
            self, with the fitted attributes set.

        Notes
        -----
        The fit runs on one BLAS thread whatever the caller's setting: hundreds of L-BFGS-B
        iterations carry the last-bit differences between thread counts' sums to another
        optimum, so a fit is reproducible wherever it runs (a fitted model is cached
        under a key that knows nothing of threads).
        """
        with threadpool_limits(1):
            return self._fit(Y)

    def _fit(self, Y: np.ndarray) -> GPLVM:
        """:meth:`fit`, inside its one-thread block."""
        Y = _check_rows("GPLVM.fit", "Y", Y, None)
        N, D = Y.shape
        self._check_options(N, D)
        q, bc = int(self.n_components), self.back_constraint
        Y_mean = Y.mean(0)
        Yc = Y - Y_mean
        scale = float(np.sqrt(np.mean(Yc * Yc)))
        if not scale > 0:
            raise InputError("GPLVM.fit: Y has no variance (all rows identical)")
        Ys = Yc / scale
        svd = np.linalg.svd(Ys, full_matrices=False)  # once: the PCA start and LatentProblem
        if self.init is not None:
            X0 = _check_rows("GPLVM.fit", "init", self.init, q)
            if len(X0) != N:
                raise InputError(
                    f"GPLVM.fit: init must have shape ({N}, {q}) for {N} poses, found {X0.shape}"
                )
        else:  # PCA initialisation, sign fixed so the largest loading of each axis is positive
            Vt = svd[2][:q]
            Vt = Vt * np.sign(Vt[np.arange(q), np.argmax(np.abs(Vt), 1)])[:, None]
            X0 = Ys @ Vt.T
            X0 /= max(float(X0[:, 0].std()), NORM_FLOOR)

        Kbc, bc_gamma, w0 = None, float("nan"), []
        if bc == "rbf":
            d2y = sqdist(Ys)
            pair = d2y[np.triu_indices(N, 1)]
            pair = pair[pair > 0]  # duplicated rows would bias the median heuristic to 0
            bc_gamma = (
                float(self.bc_gamma) if self.bc_gamma is not None else 1.0 / float(np.median(pair))
            )
            Kbc = rbf(d2y, 1.0, bc_gamma)
            # A0: least squares K_bc A0 ≈ X0 (the ridge keeps it bounded when K_bc is
            # near singular)
            w0 = [np.linalg.solve(Kbc + _BACK_RIDGE * np.eye(N), X0)]
        elif bc == "mlp":
            H = int(self.n_hidden)
            rng = np.random.default_rng(self.random_state)
            W1 = rng.standard_normal((D, H)) / np.sqrt(D)
            b1 = 0.5 * rng.standard_normal(H)
            Hd = np.tanh(Ys @ W1 + b1)
            Hb = np.hstack([Hd, np.ones((N, 1))])  # W2, b2 by least squares onto X0
            sol = np.linalg.lstsq(Hb, X0, rcond=None)[0]
            w0 = [W1, b1, sol[:H], sol[H]]
        else:
            w0 = [X0]
        prob = LatentProblem(Ys, q, bc, Kbc=Kbc, n_hidden=int(self.n_hidden), svd=svd)
        logs = np.log([self.alpha, self.gamma, self.beta])
        phi0 = prob.from_model(np.concatenate([logs, *[w.ravel() for w in w0]]))
        bounds = _HYPER_BOUNDS + [(None, None)] * (phi0.size - 3)
        last: dict[bytes, float] = {}

        def fun(phi):
            f, g = prob.in_optimiser_coords(phi)
            last[phi.tobytes()] = f
            return f, g

        history = [-fun(phi0)[0]]

        def callback(phi):  # called once per iteration with the accepted point
            f = last.get(phi.tobytes())
            history.append(-(f if f is not None else fun(phi)[0]))
            last.clear()

        res = minimize(
            fun,
            phi0,
            jac=True,
            method="L-BFGS-B",
            bounds=bounds,
            callback=callback,
            options={
                "maxiter": int(self.max_iter),
                "ftol": float(self.tol),
                "gtol": float(self.tol) * N * D,
                "maxcor": 20,
            },
        )
        res.x = prob.to_model(res.x)
        alpha, gamma, beta, w = prob.unpack(res.x)
        X, _ = prob.latent(w)
        self.alpha_, self.gamma_, self.beta_ = alpha, gamma, beta
        self.X_ = X
        self.A_ = w[0] if bc == "rbf" else None
        self.mlp_weights_ = tuple(w) if bc == "mlp" else None
        self.bc_gamma_ = bc_gamma
        self.Y_, self.Y_mean_, self.Y_scale_ = Ys, Y_mean, scale
        self.n_iter_ = int(res.nit)
        self.log_likelihood_ = float(-res.fun)
        self.log_likelihood_history_ = np.asarray(history, dtype=np.float64)
        self.converged_ = bool(res.status == 0)
        self._precompute()
        return self

    def _precompute(self) -> None:
        """K⁻¹, K⁻¹Y and the stacked operator of the prediction hot path."""
        N = self.X_.shape[0]
        K = rbf(sqdist(self.X_), self.alpha_, self.gamma_) + np.eye(N) / self.beta_
        self.Kinv_, _ = chol_inverse(K)
        self.KinvY_ = self.Kinv_ @ self.Y_
        self._hot_path()

    def _hot_path(self) -> None:
        # PT = [s K⁻¹Y, K⁻¹] (N, D + N): one product gives Eq. (7), (8) and K⁻¹k_x
        self._PT = np.ascontiguousarray(np.hstack([self.Y_scale_ * self.KinvY_, self.Kinv_]))
        self._XT = np.ascontiguousarray(self.X_.T)
        self._D = self.Y_.shape[1]

    def _fitted(self, func: str) -> None:
        if not hasattr(self, "X_"):
            raise InputError(f"GPLVM.{func}: this GPLVM is not fitted yet; call fit(Y) first")

    # -- mapping poses to latent points -------------------------------------------------------
    def transform(self, Y: np.ndarray) -> np.ndarray:
        """Latent points of poses through the back-constraint.

        Parameters
        ----------
        Y : (M, D) array_like of float
            Poses in the original data units.

        Returns
        -------
        (M, q) float64
            g(Y): ``K_bc(Y, Y_) A_`` (``"rbf"``) or the MLP output (``"mlp"``).
        """
        self._fitted("transform")
        Y = _check_rows("GPLVM.transform", "Y", Y, self.Y_.shape[1])
        Ys = (Y - self.Y_mean_) / self.Y_scale_
        if self.back_constraint == "rbf":
            return rbf(sqdist(Ys, self.Y_), 1.0, self.bc_gamma_) @ self.A_
        if self.back_constraint == "mlp":
            W1, b1, W2, b2 = self.mlp_weights_
            return np.tanh(Ys @ W1 + b1) @ W2 + b2
        raise InputError(
            "GPLVM.transform: needs a back-constraint; this model was fitted "
            "with back_constraint=None"
        )

    def fit_transform(self, Y: np.ndarray, y: None = None) -> np.ndarray:
        """``fit(Y)`` then return ``X_`` (N, q)."""
        return self.fit(Y).X_

    # -- prediction ---------------------------------------------------------------------------
    def predict(
        self, X: np.ndarray, return_var: bool = False
    ) -> np.ndarray | tuple[np.ndarray, np.ndarray]:
        """Predictive mean (Eq. (7)) and variance (Eq. (9)) of the poses at latent points.

        Parameters
        ----------
        X : (M, q) array_like of float
            Latent points.
        return_var : bool
            Also return the variance.

        Returns
        -------
        mean : (M, D) float64
            Mean poses in the original data units.
        var : (M,) float64
            Predictive variance of every pose channel, in squared data units (only with
            ``return_var``); noise-free, ≥ 0.
        """
        self._fitted("predict")
        X = _check_rows("GPLVM.predict", "X", X, self.X_.shape[1])
        Kx = rbf(sqdist(X, self.X_), self.alpha_, self.gamma_)  # (M, N), Eq. (3)
        mean = self.Y_mean_ + self.Y_scale_ * (Kx @ self.KinvY_)  # Eq. (7)
        if not return_var:
            return mean
        var = self.alpha_ - np.einsum("mn,mn->m", Kx @ self.Kinv_, Kx)  # Eq. (9)
        return mean, np.maximum(var, 0.0) * self.Y_scale_**2

    def predict_with_gradient(
        self, x: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, float, np.ndarray]:
        """Mean, variance and their gradients at ONE latent point (the tracker's hot path).

        Parameters
        ----------
        x : (q,) array_like of float
            Latent point.

        Returns
        -------
        mean : (D,) float64
            Eq. (7), original data units.
        dmean : (D, q) float64
            d mean / dx, Eq. (8).
        var : float
            Eq. (9), squared data units (not clipped: may be ~-1e-12 at a training point).
        dvar : (q,) float64
            d var / dx, Eq. (10).
        """
        try:
            PT, XT, D = self._PT, self._XT, self._D
        except AttributeError:
            self._fitted("predict_with_gradient")
            raise
        x = np.asarray(x, dtype=np.float64)
        q = XT.shape[0]
        if x.shape != (q,):
            raise InputError(
                f"GPLVM.predict_with_gradient: x must have shape ({q},), found {x.shape}"
            )
        J = np.empty((q + 1, XT.shape[1]))  # rows: k_x, then dk_x/dx transposed
        diff = np.subtract(XT, x[:, None], out=J[1:])  # x_i - x, (q, N)
        kx = np.exp(np.einsum("ij,ij->j", diff, diff) * (-0.5 * self.gamma_))
        kx *= self.alpha_  # Eq. (3)
        J[0] = kx
        diff *= self.gamma_ * kx  # dk_x/dx = γ (x_i - x) k_x
        R = J @ PT  # [k_x, dk_x/dx]ᵀ [s K⁻¹Y, K⁻¹]: one pass over the (N, D + N) operator
        s2 = self.Y_scale_ * self.Y_scale_
        mean = self.Y_mean_ + R[0, :D]  # Eq. (7)
        dmean = R[1:, :D].T  # Eq. (8)
        var = s2 * (self.alpha_ - kx @ R[0, D:])  # Eq. (9), k(x, x) = α
        dvar = (-2.0 * s2) * (R[1:, D:] @ kx)  # Eq. (10), dk(x, x)/dx = 0
        return mean, dmean, float(var), dvar

    # -- persistence --------------------------------------------------------------------------
    def save(self, path: str | os.PathLike, *, extra: dict[str, np.ndarray] | None = None) -> Path:
        """Write the fitted model to an ``.npz`` file atomically; returns the path.

        ``extra`` arrays are stored beside the model under their own names (which must not
        clash with the model's); :meth:`load` ignores them.
        """
        self._fitted("save")
        path = Path(path)
        opts = self.get_params()
        opts["init"] = None  # the start of a fit, not part of the model
        if not isinstance(opts["random_state"], int | type(None)):
            opts["random_state"] = None  # a Generator is not serialisable
        arrays = {
            "kind": np.array(_KIND),
            "format_version": np.array(FORMAT_VERSION),
            "options": np.array(json.dumps(opts)),
            "X_": self.X_,
            "Y_": self.Y_,
            "Y_mean_": self.Y_mean_,
            "Kinv_": self.Kinv_,
            "KinvY_": self.KinvY_,
            "history": self.log_likelihood_history_,
            "scalars": np.array(
                [
                    self.alpha_,
                    self.gamma_,
                    self.beta_,
                    self.bc_gamma_,
                    self.Y_scale_,
                    self.log_likelihood_,
                    self.n_iter_,
                    float(self.converged_),
                ]
            ),
        }
        if self.A_ is not None:
            arrays["A_"] = self.A_
        if self.mlp_weights_ is not None:
            arrays.update({f"mlp{i}": w for i, w in enumerate(self.mlp_weights_)})
        clash = sorted(set(extra or {}) & set(arrays))
        if clash:
            raise InputError(f"GPLVM.save: extra arrays {clash} clash with the model's own")
        arrays.update(extra or {})
        with atomic_open(path, "wb") as f:
            np.savez(f, **arrays)
        return path

    @classmethod
    def load(cls, path: str | os.PathLike) -> GPLVM:
        """Read a model written by :meth:`save`; predictions are bit-for-bit identical."""
        path = Path(path)
        if not path.is_file():
            raise MeshmocapFileNotFoundError(f"{path}: no such GPLVM file")
        d = read_npz(path, "GPLVM file")
        if str(d.get("kind", "")) != _KIND:
            raise FormatError(f"{path}: not a meshmocap GPLVM file")
        try:
            return cls._from_arrays(d, path)
        except (KeyError, ValueError, TypeError, IndexError, np.linalg.LinAlgError) as e:
            why = f"{type(e).__name__}: {e}".splitlines()[0][:160]
            raise FormatError(f"{path}: corrupt GPLVM file ({why})") from None

    @classmethod
    def _from_arrays(cls, d: dict, path: Path) -> GPLVM:
        version = int(d["format_version"])
        if version != FORMAT_VERSION:
            raise FormatError(
                f"{path}: GPLVM format version {version}, "
                f"this meshmocap reads version {FORMAT_VERSION}"
            )
        self = cls(**json.loads(str(d["options"])))
        a, g, b, bcg, s, ll, nit, conv = d["scalars"].tolist()
        self.alpha_, self.gamma_, self.beta_, self.bc_gamma_ = a, g, b, bcg
        self.Y_scale_, self.log_likelihood_, self.n_iter_, self.converged_ = (
            s,
            ll,
            int(nit),
            bool(conv),
        )
        keys = [
            "X_",
            "Y_",
            "Y_mean_",
            "history",
            "Kinv_",
            "KinvY_",
            "A_",
            *(f"mlp{i}" for i in range(4)),
        ]
        for key in (k for k in keys if k in d):
            a = d[key]
            if a.dtype.kind not in "fiu" or not np.isfinite(a).all():
                raise ValueError(f"{key} must hold finite real numbers, found {a.dtype}")
            d[key] = a.astype(np.float64)
        self.X_, self.Y_, self.Y_mean_ = d["X_"], d["Y_"], d["Y_mean_"]
        self.log_likelihood_history_ = d["history"]
        self.A_ = d.get("A_")
        mlp = [d[f"mlp{i}"] for i in range(4) if f"mlp{i}" in d]
        self.mlp_weights_ = tuple(mlp) if mlp else None
        self.Kinv_, self.KinvY_ = d["Kinv_"], d["KinvY_"]
        self._hot_path()
        return self
