"""Body-part classification of observed points (patch tracker, Huang et al. 2013, §III-B).

Each frame a linear multi-class classifier with probability outputs is trained on the
previous frame's fitted mesh — vertex 3-D positions (metres) → body-part labels — and sorts
the points observed in the next frame into three sets by the probability ``p`` of their
most likely label, Eq. (6):

* on-bone ``T_b`` (``p > 0.9``): only a fraction is kept (a speed knob, Fig. 8);
* near-joint ``T_g`` (``0.5 < p ≤ 0.9``): all kept, joints need the observations;
* outliers ``T_o`` (``p ≤ 0.5``): dropped.

Methods (:class:`BodyPartClassifier`), measured by ``benchmarks/bench_bodyparts.py``:

``"svc"`` (default)
    What the paper used: libsvm's linear C-SVC, Eq. (4)–(5), one-vs-one, with libsvm's
    ``-b 1`` probabilities — a Platt sigmoid per pair of classes fitted on 5-fold
    out-of-fold decision values (Lin, Lin & Weng 2007), the pairs coupled into class
    posteriors (Wu, Lin & Weng 2004, method 2). scikit-learn 1.9 deprecates
    ``SVC(probability=True)`` (gone in 1.11), so the same algorithm is written here around
    scikit-learn's libsvm ``SVC``. The replacement scikit-learn suggests,
    ``CalibratedClassifierCV(SVC(kernel="linear"), method="sigmoid")``, calibrates
    one-vs-rest vote counts instead: half of its misclassified points got p > 0.9 (kept
    as on-bone by Eq. (6)) against 1–3 % here.
``"logistic"``
    Multinomial logistic regression: scikit-learn's ``LogisticRegression`` loss (L2, ``C``),
    minimised by Newton's method to a gradient of 1e-7 (from the last frame's fit: 3–4
    Hessians and ~6 passes over the points; scikit-learn's L-BFGS stops at 1e-4 after
    ~30 passes); two classes by scikit-learn's L-BFGS. As accurate in labels (within 0.7
    points on the walk benchmark) and 20–35× faster to predict, but its probabilities sort points
    less well for Eq. (6): 5–8 % of its errors have p > 0.9 (svc: 0.5–3 %), and it calls
    2–4 % of the visual hull's phantom points outliers (svc: 19–33 %). It also loses
    fewer real surface points at the joints (1 % of them get p ≤ 0.5; svc: 5–6 %).

Both models see standardised coordinates (centred on the training cloud's mean, divided
by its per-axis standard deviation) and at most ``max_train`` training vertices, drawn by
a seeded stratified subsample.

A linear model is confident far from the body: a blob 30 cm in front of the chest is
labelled thorax, with the 10 bone labels, at p > 0.9 by both methods; with the 15 parts
``"svc"`` calls about 15 % of it outliers, ``"logistic"`` none. Only points near boundaries
between parts get p ≤ 0.5. :func:`partition`'s ``max_distance`` (an extension, off by
default) also drops points farther than a given distance from every training point.

References
----------
- C.-H. Huang, E. Boyer, S. Ilic, *Robust human body shape and pose tracking*,
  International Conference on 3D Vision (3DV), 2013.
- H.-T. Lin, C.-J. Lin, R. C. Weng, *A note on Platt's probabilistic outputs for
  support vector machines*, Machine Learning 68(3):267–276, 2007.
  https://doi.org/10.1007/s10994-007-5018-6
- T.-F. Wu, C.-J. Lin, R. C. Weng, *Probability estimates for multi-class
  classification by pairwise coupling*, Journal of Machine Learning Research
  5:975–1005, 2004.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal, get_args

import numpy as np
from scipy.special import expit
from sklearn.linear_model import LogisticRegression
from sklearn.svm import SVC

from meshmocap._tolerances import DIVISOR_FLOOR, ROUNDING_SLACK
from meshmocap._validate import check_choice
from meshmocap.errors import InputError
from meshmocap.geometry.nearby import farther_than
from meshmocap.models._softmax import SoftmaxRegression

Method = Literal["svc", "logistic"]
METHODS: tuple[str, ...] = get_args(Method)

#: Point kinds of Eq. (6), the values of :attr:`Partition.kind`.
ON_BONE, NEAR_JOINT, OUTLIER = 0, 1, 2

_CV_FOLDS = 5  # folds of the out-of-fold decision values the Platt sigmoids are fitted on
_CHUNK = 2048  # points per batch of the pairwise coupling
#: Shortest line-search step of Platt's Newton fit (libsvm's value).
_PLATT_MIN_STEP = 1e-10
_MAX_Z = 16.118  # |A f + B| cap: libsvm clips pairwise probabilities to [1e-7, 1 − 1e-7]
_MIN_PER_CLASS = 5  # the stratified subsample keeps at least this many of each label
_LOGISTIC_MAX_ITER = 2000  # two classes: scikit-learn's L-BFGS (more: _softmax's Newton)


def _check_points(func: str, name: str, X: object) -> np.ndarray:
    """``X`` as a finite (n, 3) float64 array."""
    try:
        A = np.asarray(X, dtype=np.float64)
    except (TypeError, ValueError):
        raise InputError(
            f"{func}: {name} must be an (n, 3) float array of metres, found {type(X).__name__}"
        ) from None
    if A.ndim != 2 or A.shape[1] != 3:
        raise InputError(f"{func}: {name} must have shape (n, 3), found {A.shape}")
    if not np.isfinite(A).all():
        raise InputError(
            f"{func}: {name} has {int((~np.isfinite(A)).any(1).sum())} non-finite rows"
        )
    return A


def _stratified_subset(labels: np.ndarray, n_keep: int, rng: np.random.Generator) -> np.ndarray:
    """Sorted indices of about ``n_keep`` rows, each label in proportion (≥ 5 where it can)."""
    n = len(labels)
    if n <= n_keep:
        return np.arange(n)
    _, inv, counts = np.unique(labels, return_inverse=True, return_counts=True)
    quota = np.maximum(
        np.floor(counts * (n_keep / n)).astype(np.int64), np.minimum(counts, _MIN_PER_CLASS)
    )
    order = rng.permutation(n)
    grouped = order[np.argsort(inv[order], kind="stable")]  # random order within each label
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
    take = np.concatenate([grouped[s : s + q] for s, q in zip(starts, quota, strict=True)])
    return np.sort(take)


def platt_sigmoid(f: np.ndarray, positive: np.ndarray) -> tuple[float, float]:
    """Platt sigmoid ``P(positive | f) = 1 / (1 + exp(A f + B))`` fitted to decision values.

    libsvm's ``sigmoid_train``: Newton's method with backtracking on the regularised
    targets of Lin, Lin & Weng (2007). ``f`` (n,) float64, ``positive`` (n,) bool.
    """
    n1 = int(positive.sum())
    n0 = len(f) - n1
    t = np.where(positive, (n1 + 1.0) / (n1 + 2.0), 1.0 / (n0 + 2.0))

    def objective(A: float, B: float) -> float:
        z = A * f + B
        return float(np.sum(t * z + np.logaddexp(0.0, -z)))

    A, B = 0.0, float(np.log((n0 + 1.0) / (n1 + 1.0)))
    value = objective(A, B)
    for _ in range(100):
        p = expit(-(A * f + B))  # P(positive)
        d1, d2 = t - p, p * (1.0 - p)
        g1, g2 = float(f @ d1), float(d1.sum())
        if abs(g1) < 1e-5 and abs(g2) < 1e-5:
            break
        h11, h22, h21 = (
            float(f * f @ d2) + DIVISOR_FLOOR,
            float(d2.sum()) + DIVISOR_FLOOR,
            float(f @ d2),
        )
        det = h11 * h22 - h21 * h21
        dA, dB = -(h22 * g1 - h21 * g2) / det, -(-h21 * g1 + h11 * g2) / det
        gd, step = g1 * dA + g2 * dB, 1.0
        while step >= _PLATT_MIN_STEP:
            new = objective(A + step * dA, B + step * dB)
            if new < value + 1e-4 * step * gd:
                A, B, value = A + step * dA, B + step * dB, new
                break
            step /= 2.0
        else:
            break  # line search failed: keep the last iterate, as libsvm does
    return A, B


def coupled_probabilities(rij: np.ndarray, pairs: np.ndarray, K: int) -> np.ndarray:
    """Class posteriors from pairwise probabilities (Wu, Lin & Weng 2004, method 2).

    Parameters
    ----------
    rij : (m, P) float64
        ``rij[:, c]`` = P(class i | class i or j, x) for ``(i, j) = pairs[c]``, in (0, 1).
    pairs : (P, 2) int64
        Every pair ``i < j`` of ``range(K)`` once.
    K : int
        Number of classes.

    Returns
    -------
    (m, K) float64
        The minimiser of ``Σ_i Σ_{j≠i} (r_ji p_i − r_ij p_j)²`` subject to ``Σ p = 1``, with
        ``r_ji = 1 − r_ij`` (libsvm's ``multiclass_probability`` solves the same problem
        iteratively, to a tolerance of 0.005 / K).
    """
    m = len(rij)
    i, j = pairs[:, 0], pairs[:, 1]
    first = np.zeros((len(pairs), K))
    first[np.arange(len(pairs)), i] = 1.0
    second = np.zeros((len(pairs), K))
    second[np.arange(len(pairs)), j] = 1.0
    n = K + 1
    upper, lower, diag = i * n + j, j * n + i, np.arange(K) * (n + 1)
    border = np.concatenate([np.arange(K) * n + K, K * n + np.arange(K)])
    out = np.empty((m, K))
    # Stationarity with the constraint's multiplier b: Q p − b e = 0, eᵀp = 1, where
    # Q_ij = Q_ji = −r_ij r_ji and Q_ii = Σ_{j≠i} r_ji²; Q is only semi-definite (singular
    # when the r_ij are consistent), the bordered system is not. Chunks stay in cache.
    for s in range(0, m, _CHUNK):
        r = rij[s : s + _CHUNK]
        M = np.zeros((len(r), n * n))
        M[:, upper] = M[:, lower] = -r * (1.0 - r)
        M[:, diag] = (1.0 - r) ** 2 @ first + r**2 @ second
        M[:, border] = 1.0
        rhs = np.zeros((len(r), n, 1))
        rhs[:, K] = 1.0
        out[s : s + _CHUNK] = np.linalg.solve(M.reshape(-1, n, n), rhs)[:, :K, 0]
    np.clip(out, 0.0, None, out=out)  # non-negative in exact arithmetic (Wu et al. 2004)
    return out / out.sum(1, keepdims=True)


class _PairwiseSVC:
    """Linear one-vs-one C-SVC with libsvm's ``-b 1`` probabilities (module docstring)."""

    def __init__(self, C: float) -> None:
        self.C = C

    @staticmethod
    def _decision(svc: SVC, Z: np.ndarray) -> np.ndarray:
        # Linear kernel: the pairwise decision values are affine; (m, K(K-1)/2).
        return Z @ svc.coef_.T + svc.intercept_

    def fit(self, Z: np.ndarray, y: np.ndarray, rng: np.random.Generator) -> _PairwiseSVC:
        classes, inv, counts = np.unique(y, return_inverse=True, return_counts=True)
        K = len(classes)
        folds = int(min(_CV_FOLDS, counts.min()))
        fold = np.empty(len(y), dtype=np.int64)  # stratified: each class spread over folds
        for k in range(K):
            members = np.flatnonzero(inv == k)
            fold[rng.permutation(members)] = np.arange(len(members)) % folds
        pairs = [(i, j) for i in range(K) for j in range(i + 1, K)]  # libsvm's pair order
        F = np.empty((len(y), len(pairs)))
        for k in range(folds):
            test = fold == k
            svc = SVC(kernel="linear", C=self.C).fit(Z[~test], y[~test])
            F[test] = self._decision(svc, Z[test])
        platt = np.empty((len(pairs), 2))
        for c, (i, j) in enumerate(pairs):
            rows = (inv == i) | (inv == j)
            platt[c] = platt_sigmoid(F[rows, c], inv[rows] == i)
        self.svc_ = SVC(kernel="linear", C=self.C).fit(Z, y)
        self.classes_ = classes
        self.pairs_ = np.array(pairs, dtype=np.int64).reshape(-1, 2)
        self.platt_ = platt
        return self

    def predict_proba(self, Z: np.ndarray) -> np.ndarray:
        F = self._decision(self.svc_, Z)
        # P(first of the pair) = 1 / (1 + exp(A f + B)), clipped to [1e-7, 1 − 1e-7] as libsvm
        z = F * self.platt_[:, 0] + self.platt_[:, 1]
        np.clip(z, -_MAX_Z, _MAX_Z, out=z)
        np.exp(z, out=z)
        z += 1.0
        rij = np.reciprocal(z, out=z)
        return coupled_probabilities(rij, self.pairs_, len(self.classes_))


def _initial_logits(
    method: str, classes: np.ndarray, coef: object, intercept: object
) -> tuple[np.ndarray, np.ndarray] | None:
    """Checked ``(coef (k, 3), intercept (k,))`` of :meth:`BodyPartClassifier.fit`, or None;
    ``k`` is the number of classes (1 for two classes, as scikit-learn's)."""
    if coef is None and intercept is None:
        return None
    func = "BodyPartClassifier.fit"
    if method != "logistic":
        raise InputError(f"{func}: coef_init applies to method 'logistic' only, found {method!r}")
    k = len(classes) if len(classes) > 2 else 1
    try:
        W = np.asarray(coef, dtype=np.float64)
        b = np.asarray(intercept, dtype=np.float64)
    except (TypeError, ValueError):
        raise InputError(f"{func}: coef_init and intercept_init must be float arrays") from None
    if W.shape != (k, 3) or b.shape != (k,):
        raise InputError(
            f"{func}: coef_init and intercept_init must have shapes ({k}, 3) "
            f"and ({k},) for {len(classes)} labels, found {W.shape} and "
            f"{b.shape}"
        )
    if not (np.isfinite(W).all() and np.isfinite(b).all()):
        raise InputError(f"{func}: coef_init and intercept_init must be finite")
    return W, b


class BodyPartClassifier:
    """Linear multi-class classifier of 3-D points into body parts, with probabilities.

    Follows the scikit-learn contract: ``__init__`` only stores the options, :meth:`fit`
    returns ``self`` and sets the trailing-underscore attributes.

    Parameters
    ----------
    method : {"svc", "logistic"}
        ``"svc"``: linear C-SVC (libsvm, one-vs-one) with libsvm's pairwise Platt
        probabilities, as in the paper; ``"logistic"``: multinomial logistic regression,
        faster but less discerning in its probabilities (module docstring).
    C : float
        Inverse regularisation strength (> 0) of either model, on standardised
        coordinates. The default 100 is larger than libsvm's 1: at C = 1 both models
        underfit the 15 body parts of ``neutral_5k`` (next-frame accuracy 94.2 % svc,
        91 % logistic, against 96.2 % and 95.7 % at C = 100).
    max_train : int
        Most training vertices (≥ 10); larger training sets are subsampled, stratified by
        label, with ``random_state``.
    random_state : int, numpy.random.Generator or None
        Seeds the training subsample and ``"svc"``'s cross-validation folds.

    Attributes
    ----------
    classes_ : (K,) int64
        Sorted distinct training labels; columns of :meth:`predict_proba`.
    model_ : SoftmaxRegression, LogisticRegression (two classes) or _PairwiseSVC
        The fitted model, on standardised coordinates (``"svc"``: the libsvm ``SVC`` is
        ``model_.svc_``, the pairwise Platt sigmoids ``model_.platt_``).
    mean_ : (3,) float64
        Mean of the training points, metres.
    scale_ : (3,) float64
        Per-axis standard deviation of the training points, metres (1 where zero).
    n_train_ : int
        Number of training vertices the model saw (after subsampling).
    points_ : (n, 3) float64
        All the training points given to :meth:`fit`, metres (for
        ``partition(max_distance=)``).
    coef_, intercept_ : (k, 3), (k,) float64
        ``"logistic"`` only: the fitted logits on world coordinates, ``coef_ @ x +
        intercept_`` (``k`` = number of classes, 1 for two), for ``fit(coef_init=)``.
    """

    _PARAMS = ("method", "C", "max_train", "random_state")

    def __init__(
        self,
        method: Method = "svc",
        *,
        C: float = 100.0,
        max_train: int = 3000,
        random_state: int | np.random.Generator | None = None,
    ) -> None:
        self.method = method
        self.C = C
        self.max_train = max_train
        self.random_state = random_state

    # -- scikit-learn plumbing ------------------------------------------------------------
    def get_params(self, deep: bool = True) -> dict:
        """The constructor options, as a dict."""
        return {k: getattr(self, k) for k in self._PARAMS}

    def set_params(self, **params) -> BodyPartClassifier:
        """Set constructor options; returns self."""
        for k, v in params.items():
            if k not in self._PARAMS:
                raise InputError(f"BodyPartClassifier.set_params: unknown option {k!r}")
            setattr(self, k, v)
        return self

    def __repr__(self) -> str:
        return f"BodyPartClassifier({self.method!r}, C={self.C!r}, max_train={self.max_train!r})"

    def _check_options(self) -> None:
        check_choice("BodyPartClassifier", "method", self.method, METHODS)
        C = self.C
        if isinstance(C, bool) or not (np.isscalar(C) and np.isfinite(C) and C > 0):
            raise InputError(f"BodyPartClassifier: C must be a positive float, found {C!r}")
        m = self.max_train
        if isinstance(m, bool) or not isinstance(m, int | np.integer) or m < 10:
            raise InputError(f"BodyPartClassifier: max_train must be an int ≥ 10, found {m!r}")

    # -- training ---------------------------------------------------------------------------
    def fit(
        self,
        X: np.ndarray,
        labels: np.ndarray,
        *,
        coef_init: np.ndarray | None = None,
        intercept_init: np.ndarray | None = None,
    ) -> BodyPartClassifier:
        """Learn body parts from labelled points (the previous frame's fitted vertices).

        Parameters
        ----------
        X : (n, 3) array_like of float
            Training points, metres, world frame.
        labels : (n,) array_like of int
            Body-part label of each point (any integers, at least two distinct; with
            ``"svc"`` each label needs at least two points).
        coef_init, intercept_init : array_like, optional
            ``"logistic"`` only: the starting point of the fit, as world-frame logits
            ``coef_init @ x + intercept_init`` (the ``coef_`` and ``intercept_`` of
            an earlier fit with the same labels). The optimum does not depend on it; from
            the previous frame's fit a tracker's next fit takes ~6 Newton steps on 3–4
            Hessians instead of 13–16 steps on 12–14 (the 12k walk at 60 fps).

        Returns
        -------
        BodyPartClassifier
            self, with the fitted attributes set.
        """
        self._check_options()
        X = _check_points("BodyPartClassifier.fit", "X", X)
        lab = np.asarray(labels)
        if lab.shape != (len(X),):
            raise InputError(
                f"BodyPartClassifier.fit: labels must have shape ({len(X)},) "
                f"to match X, found {lab.shape}"
            )
        if not np.issubdtype(lab.dtype, np.integer):
            raise InputError(f"BodyPartClassifier.fit: labels must be integers, found {lab.dtype}")
        lab = lab.astype(np.int64)
        classes, counts = np.unique(lab, return_counts=True)
        if len(classes) < 2:
            raise InputError(
                f"BodyPartClassifier.fit: labels must hold at least 2 distinct "
                f"values, found {len(classes)}"
            )
        if self.method == "svc" and counts.min() < 2:
            raise InputError(
                f"BodyPartClassifier.fit: with method 'svc' every label needs ≥ 2 "
                f"points (Platt cross-validation), label "
                f"{int(classes[counts.argmin()])} has 1"
            )

        rng = np.random.default_rng(self.random_state)
        idx = _stratified_subset(lab, int(self.max_train), rng)
        Xt, yt = X[idx], lab[idx]
        mean = Xt.mean(0)
        scale = Xt.std(0)
        scale[scale <= 0] = 1.0
        Z = (Xt - mean) / scale
        C = float(self.C)
        start = _initial_logits(self.method, classes, coef_init, intercept_init)
        if self.method == "svc":
            model = _PairwiseSVC(C).fit(Z, yt, rng)
        elif len(classes) > 2:
            if start is not None:  # world logits W x + b = (W s) z + (b + W μ), z = (x − μ)/s
                start = (start[0] * scale, start[1] + start[0] @ mean)
            model = SoftmaxRegression(C, len(classes)).fit(Z, np.searchsorted(classes, yt), start)
            self.coef_ = model.coef_ / scale  # the same logits on world coordinates
            self.intercept_ = model.intercept_ - self.coef_ @ mean
        else:
            warm = start is not None
            model = LogisticRegression(C=C, max_iter=_LOGISTIC_MAX_ITER, warm_start=warm)
            if warm:  # world logits W x + b = (W s) z + (b + W μ), z = (x − μ)/s
                model.coef_ = start[0] * scale
                model.intercept_ = start[1] + start[0] @ mean
            model.fit(Z, yt)
            self.coef_ = model.coef_ / scale  # the same logits on world coordinates
            self.intercept_ = model.intercept_ - self.coef_ @ mean

        self.classes_ = classes
        self.model_ = model
        self.mean_ = mean
        self.scale_ = scale
        self.n_train_ = len(idx)
        self.points_ = np.ascontiguousarray(X, dtype=np.float64)
        return self

    # -- prediction -------------------------------------------------------------------------
    def _check_fitted(self, func: str) -> None:
        if not hasattr(self, "model_"):
            raise InputError(
                f"BodyPartClassifier.{func}: the classifier is not fitted; "
                "call fit(X, labels) first"
            )

    def predict_proba(self, Y: np.ndarray) -> np.ndarray:
        """Posterior probability of every body part for each point.

        Parameters
        ----------
        Y : (m, 3) array_like of float
            Observed points, metres, same frame as the training points.

        Returns
        -------
        (m, K) float64
            Rows in [0, 1] summing to 1; column k is ``classes_[k]``.
        """
        self._check_fitted("predict_proba")
        Y = _check_points("BodyPartClassifier.predict_proba", "Y", Y)
        if len(Y) == 0:
            return np.empty((0, len(self.classes_)))
        P = self.model_.predict_proba((Y - self.mean_) / self.scale_)
        return np.asarray(P, dtype=np.float64)

    def predict(self, Y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Most likely body part of each point and its probability.

        Parameters
        ----------
        Y : (m, 3) array_like of float
            Observed points, metres.

        Returns
        -------
        labels : (m,) int64
            Most likely label (a value of ``classes_``).
        p : (m,) float64
            Its posterior probability, in [1/K, 1].
        """
        self._check_fitted("predict")
        P = self.predict_proba(Y)
        k = P.argmax(1)
        return self.classes_[k], P[np.arange(len(P)), k]


@dataclass(frozen=True, eq=False)
class Partition:
    """Observed points sorted by :func:`partition`, Eq. (6).

    Attributes
    ----------
    labels : (m,) int64
        Most likely body part of each point.
    prob : (m,) float64
        Its posterior probability.
    kind : (m,) int8
        :data:`ON_BONE` (0), :data:`NEAR_JOINT` (1) or :data:`OUTLIER` (2).
    keep : (m,) bool
        Points passed on to the tracker: every near-joint point and a random fraction of
        the on-bone points; never an outlier.
    """

    labels: np.ndarray
    prob: np.ndarray
    kind: np.ndarray
    keep: np.ndarray

    @property
    def counts(self) -> tuple[int, int, int]:
        """Numbers of on-bone, near-joint and outlier points."""
        c = np.bincount(self.kind, minlength=3)
        return int(c[ON_BONE]), int(c[NEAR_JOINT]), int(c[OUTLIER])


def partition(
    classifier: BodyPartClassifier,
    Y: np.ndarray,
    *,
    on_bone: float = 0.9,
    outlier: float = 0.5,
    keep_fraction: float = 0.3,
    max_distance: float | None = None,
    random_state: int | np.random.Generator | None = None,
) -> Partition:
    """Sort observed points into on-bone, near-joint and outlier sets, Eq. (6).

    Parameters
    ----------
    classifier : BodyPartClassifier
        Fitted on the previous frame's mesh.
    Y : (m, 3) array_like of float
        Observed points of the current frame (e.g. visual-hull vertices), metres.
    on_bone : float
        Points with ``p > on_bone`` are on a bone (paper: 0.9).
    outlier : float
        Points with ``p ≤ outlier`` are outliers (paper: 0.5); ``0 ≤ outlier < on_bone ≤ 1``.
    keep_fraction : float
        Fraction in (0, 1] of each label's on-bone points that is kept, ``ceil(fraction ×
        count)`` drawn at random per label (Fig. 8's speed/accuracy knob).
    max_distance : float or None
        Extension beyond the paper: points farther than this (metres, > 0) from every
        training point are outliers whatever their probability (a linear model is
        confident far from the body). Distances are to the training vertices, not the
        surface: keep it well above the mesh's edge length plus the motion between
        frames (0.1 works for ``neutral_5k`` at 60 fps). None (default): probabilities only.
    random_state : int, numpy.random.Generator or None
        Seeds the on-bone subsample.

    Returns
    -------
    Partition
    """
    func = "partition"
    for name, v in (("on_bone", on_bone), ("outlier", outlier), ("keep_fraction", keep_fraction)):
        if isinstance(v, bool) or not (np.isscalar(v) and np.isfinite(v)):
            raise InputError(f"{func}: {name} must be a finite float, found {v!r}")
    if not 0.0 <= outlier < on_bone <= 1.0:
        raise InputError(
            f"{func}: thresholds must satisfy 0 ≤ outlier < on_bone ≤ 1, found "
            f"outlier={outlier!r}, on_bone={on_bone!r}"
        )
    if not 0.0 < keep_fraction <= 1.0:
        raise InputError(f"{func}: keep_fraction must be in (0, 1], found {keep_fraction!r}")
    if max_distance is not None and not (
        np.isscalar(max_distance) and np.isfinite(max_distance) and max_distance > 0
    ):
        raise InputError(
            f"{func}: max_distance must be a positive float or None, found {max_distance!r}"
        )
    if not isinstance(classifier, BodyPartClassifier):
        raise InputError(
            f"{func}: classifier must be a BodyPartClassifier, found {type(classifier).__name__}"
        )
    classifier._check_fitted(func)
    Y = _check_points(func, "Y", Y)

    labels, p = classifier.predict(Y)
    kind = np.full(len(Y), NEAR_JOINT, dtype=np.int8)  # Eq. (6)
    kind[p > on_bone] = ON_BONE
    kind[p <= outlier] = OUTLIER
    if max_distance is not None and len(Y):
        kind[farther_than(Y, classifier.points_, radius=float(max_distance))] = OUTLIER

    keep = kind == NEAR_JOINT
    bone = np.flatnonzero(kind == ON_BONE)
    if keep_fraction >= 1.0:
        keep[bone] = True
    elif len(bone):
        rng = np.random.default_rng(random_state)
        bone = bone[rng.permutation(len(bone))]
        bone = bone[np.argsort(labels[bone], kind="stable")]  # random order within labels
        _, starts, counts = np.unique(labels[bone], return_index=True, return_counts=True)
        for s, c in zip(starts, counts, strict=True):
            keep[bone[s : s + math.ceil(keep_fraction * c - ROUNDING_SLACK)]] = True
    return Partition(labels=labels, prob=p, kind=kind, keep=keep)
