"""Body-part classifier and Eq. (6) partition (patch tracker §III-B).

Numbers quoted in comments were measured on ``neutral_5k`` posed by a procedural walk at
60 fps, frame 0 → frame 1 (the tracker's setting: train on the previous fitted mesh,
classify the next frame's points).
"""

from __future__ import annotations

import numpy as np
import pytest

from meshmocap.body.procedural import procedural_motion
from meshmocap.body.template import load_template
from meshmocap.errors import InputError
from meshmocap.models._softmax import (
    SoftmaxRegression,
    pair_products,
    softmax_gradient,
    softmax_hessian,
    softmax_loss,
)
from meshmocap.models.bodyparts import (
    METHODS,
    NEAR_JOINT,
    ON_BONE,
    OUTLIER,
    BodyPartClassifier,
    Partition,
    coupled_probabilities,
    partition,
    platt_sigmoid,
)

# Non-leaf bone labels the tracker uses: head→thorax, wrists→elbows, ankles→knees.
_LEAF_TO_PARENT = {2: 1, 5: 4, 8: 7, 11: 10, 14: 13}


def _bone_labels(parts: np.ndarray) -> np.ndarray:
    out = parts.copy()
    for leaf, parent in _LEAF_TO_PARENT.items():
        out[parts == leaf] = parent
    return out


@pytest.fixture(scope="module")
def walk():
    """(template, V (2, n, 3) frames 0 and 1, eval joints (2, 15, 3)) of a 60 fps walk."""
    t = load_template("neutral_5k")
    m = procedural_motion("walk", t, duration=0.1, fps=60.0)
    posed = t.pose(m.rotations[:2], m.root_positions[:2])
    return t, posed.V, posed.eval_joints


@pytest.fixture(scope="module")
def fitted(walk):
    """Classifiers trained on frame 0, keyed by (method, "parts15" | "bones10")."""
    t, V, _ = walk
    cache = {}

    def get(method: str, labels: str = "bones10") -> BodyPartClassifier:
        if (method, labels) not in cache:
            lab = t.part_labels if labels == "parts15" else _bone_labels(t.part_labels)
            cache[method, labels] = BodyPartClassifier(method, random_state=0).fit(V[0], lab)
        return cache[method, labels]

    return get


def _labels(t, name: str) -> np.ndarray:
    return t.part_labels if name == "parts15" else _bone_labels(t.part_labels)


def _blobs(n: int = 90, labels=(0, 1, 2), seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Well separated Gaussian clusters, 10 cm apart, 1 cm spread, 1 m above the floor."""
    rng = np.random.default_rng(seed)
    y = np.repeat(np.asarray(labels), n // len(labels))
    centres = np.array([[0.1 * k, 0.0, 1.0] for k in range(len(labels))])
    X = centres[np.searchsorted(np.sort(labels), y)] + rng.normal(scale=0.01, size=(len(y), 3))
    return X, y


# -- accuracy ------------------------------------------------------------------------------
@pytest.mark.parametrize("labels", ["parts15", "bones10"])
@pytest.mark.parametrize("method", METHODS)
def test_next_frame_accuracy(walk, fitted, method, labels):
    # Measured: svc 96.6 % (15 parts) / 97.8 % (10 bones); logistic 96.3 % / 97.6 %.
    # The errors sit on the boundaries between parts, where a linear split of 3-D space
    # cannot follow the mesh; 95 % is the target of the issue, ≥ 1 point of margin.
    t, V, _ = walk
    lab = _labels(t, labels)
    pred, p = fitted(method, labels).predict(V[1])
    assert np.mean(pred == lab) >= 0.95
    assert pred.dtype == np.int64 and p.dtype == np.float64


@pytest.mark.parametrize("method", METHODS)
def test_errors_are_less_sure(walk, fitted, method):
    # Eq. (6) relies on misclassified points getting low p. Measured (10 bones): median p
    # of the errors 0.54 (svc) / 0.61 (logistic) against ≥ 0.99 for correct points; errors
    # with p > 0.9 (kept as on-bone): 0.9 % (svc), 5.7 % (logistic). Bounds leave ~2×.
    t, V, _ = walk
    lab = _bone_labels(t.part_labels)
    pred, p = fitted(method).predict(V[1])
    wrong = pred != lab
    assert np.median(p[wrong]) < 0.75
    assert np.median(p[~wrong]) > 0.95
    assert np.mean(p[wrong] > 0.9) < (0.03 if method == "svc" else 0.12)


@pytest.mark.parametrize("method", METHODS)
def test_probabilities_are_distributions(walk, fitted, method):
    _, V, _ = walk
    clf = fitted(method, "parts15")
    np.testing.assert_array_equal(clf.classes_, np.arange(15))
    P = clf.predict_proba(V[1][::7])
    assert P.shape == (len(V[1][::7]), 15) and P.dtype == np.float64
    assert P.min() >= 0.0 and P.max() <= 1.0
    np.testing.assert_allclose(P.sum(1), 1.0, rtol=0, atol=1e-12)  # normalised explicitly
    labels, p = clf.predict(V[1][::7])
    np.testing.assert_array_equal(labels, clf.classes_[P.argmax(1)])
    np.testing.assert_array_equal(p, P.max(1))


# -- the libsvm probability machinery -------------------------------------------------------
def test_coupling_recovers_consistent_posteriors():
    # When r_ij = p_i / (p_i + p_j) exactly, the coupling objective is 0 at p: recovered to
    # rounding (the bordered system is well conditioned for these sizes).
    rng = np.random.default_rng(1)
    for K in (2, 3, 10):
        p = rng.dirichlet(np.ones(K), size=50)
        pairs = np.array([(i, j) for i in range(K) for j in range(i + 1, K)])
        rij = p[:, pairs[:, 0]] / (p[:, pairs[:, 0]] + p[:, pairs[:, 1]])
        np.testing.assert_allclose(coupled_probabilities(rij, pairs, K), p, rtol=0, atol=1e-10)


def test_coupling_solves_the_stationarity_conditions():
    # Inconsistent r: the minimiser of Σ_i Σ_j≠i (r_ji p_i − r_ij p_j)² on the simplex
    # satisfies Q p = b e (Wu, Lin & Weng 2004, Eq. 22); check it to 1e-10.
    rng = np.random.default_rng(2)
    K = 6
    pairs = np.array([(i, j) for i in range(K) for j in range(i + 1, K)])
    rij = rng.uniform(0.05, 0.95, size=(20, len(pairs)))
    p = coupled_probabilities(rij, pairs, K)
    np.testing.assert_allclose(p.sum(1), 1.0, atol=1e-12)
    for row, pr in zip(rij, p, strict=True):
        r = np.zeros((K, K))
        r[pairs[:, 0], pairs[:, 1]] = row
        r[pairs[:, 1], pairs[:, 0]] = 1 - row
        Q = -r.T * r
        Q[np.diag_indices(K)] = (r**2).sum(0)
        Qp = Q @ pr
        np.testing.assert_allclose(Qp, Qp.mean(), rtol=0, atol=1e-10)


def test_platt_recovers_a_sigmoid():
    # 20,000 draws from P(+|f) = 1 / (1 + exp(A f + B)), A = −2, B = 0.5: the maximum
    # likelihood estimate has a standard error ≈ 0.03 (A) and 0.02 (B); tolerance 0.15.
    rng = np.random.default_rng(3)
    f = rng.uniform(-4, 4, size=20_000)
    positive = rng.random(f.size) < 1 / (1 + np.exp(-2.0 * f + 0.5))
    A, B = platt_sigmoid(f, positive)
    assert abs(A + 2.0) < 0.15 and abs(B - 0.5) < 0.15


# -- partition, Eq. (6) ----------------------------------------------------------------------
@pytest.mark.parametrize("method", METHODS)
def test_partition_follows_the_thresholds(walk, fitted, method):
    _, V, _ = walk
    clf = fitted(method)
    part = partition(clf, V[1], random_state=0)
    assert isinstance(part, Partition) and part.kind.dtype == np.int8
    p = part.prob
    np.testing.assert_array_equal(part.kind == ON_BONE, p > 0.9)
    np.testing.assert_array_equal(part.kind == NEAR_JOINT, (p > 0.5) & (p <= 0.9))
    np.testing.assert_array_equal(part.kind == OUTLIER, p <= 0.5)
    assert sum(part.counts) == len(V[1])
    # all near-joint points kept, never an outlier
    assert part.keep[part.kind == NEAR_JOINT].all()
    assert not part.keep[part.kind == OUTLIER].any()
    # on-bone: ceil(0.3 × count) per label, so 0.3 of them up to one point per label
    bone = part.kind == ON_BONE
    kept = part.keep & bone
    for lab in np.unique(part.labels[bone]):
        n = np.sum(bone & (part.labels == lab))
        assert np.sum(kept & (part.labels == lab)) == np.ceil(0.3 * n - 1e-9)
    n_bone = bone.sum()
    assert abs(kept.sum() - 0.3 * n_bone) <= len(np.unique(part.labels))


def test_partition_is_seeded(walk, fitted):
    _, V, _ = walk
    clf = fitted("logistic")
    a = partition(clf, V[1], keep_fraction=0.5, random_state=7)
    b = partition(clf, V[1], keep_fraction=0.5, random_state=7)
    c = partition(clf, V[1], keep_fraction=0.5, random_state=8)
    np.testing.assert_array_equal(a.keep, b.keep)
    assert (a.keep != c.keep).any() and a.keep.sum() == c.keep.sum()
    full = partition(clf, V[1], keep_fraction=1.0)
    np.testing.assert_array_equal(full.keep, full.kind != OUTLIER)


def test_partition_custom_thresholds(walk, fitted):
    _, V, _ = walk
    clf = fitted("logistic")
    none_on_bone = partition(clf, V[1], on_bone=1.0, outlier=0.5)
    assert none_on_bone.counts[0] == 0
    # p ≥ 1/K > 0 for the most likely label, so outlier=0 leaves no outliers
    no_outliers = partition(clf, V[1], on_bone=0.99, outlier=0.0)
    assert no_outliers.counts[2] == 0


@pytest.mark.parametrize("method", METHODS)
def test_blob_in_front_of_the_chest(walk, fitted, method):
    # A phantom volume 30 cm in front of the chest (≥ 15 cm from the body). A linear model
    # extrapolates: with the 10 bone labels both methods call it thorax at p > 0.9 — 0.3 %
    # (svc) and 0 % (logistic) of it lands in OUTLIER. (With the 15 parts, thorax or head:
    # svc 17 %, logistic 0 %.) This documents the limitation; max_distance catches it all.
    t, V, J = walk
    torso = np.isin(t.part_labels, [0, 1]) & (np.abs(V[1][:, 2] - J[1, 1, 2]) < 0.05)
    chest = V[1][torso][np.argmin(V[1][torso][:, 1])]  # frontmost (the subject faces −Y)
    rng = np.random.default_rng(0)
    blob = chest + [0.0, -0.3, 0.0] + rng.normal(scale=0.03, size=(300, 3))
    clf = fitted(method)
    part = partition(clf, blob, random_state=0)
    assert np.mean(part.kind == OUTLIER) < 0.05
    assert np.mean(part.labels == 1) > 0.9  # thorax (measured: 99 % svc, 100 % logistic)
    gated = partition(clf, blob, max_distance=0.1, random_state=0)
    assert np.all(gated.kind == OUTLIER) and not gated.keep.any()
    # the gate leaves the next frame's own vertices (≤ 2 cm away) alone
    body = partition(clf, V[1], max_distance=0.1, random_state=0)
    np.testing.assert_array_equal(body.kind, partition(clf, V[1], random_state=0).kind)


# -- training options ----------------------------------------------------------------------
@pytest.mark.parametrize("method", METHODS)
def test_stratified_subsample(walk, method):
    t, V, _ = walk
    lab = _bone_labels(t.part_labels)
    clf = BodyPartClassifier(method, max_train=200, random_state=1).fit(V[0], lab)
    # floor(count × 200/5000) per label, at least 5: 197 here
    assert 190 <= clf.n_train_ <= 210
    np.testing.assert_array_equal(clf.classes_, np.unique(lab))
    again = BodyPartClassifier(method, max_train=200, random_state=1).fit(V[0], lab)
    np.testing.assert_array_equal(clf.predict_proba(V[1]), again.predict_proba(V[1]))
    np.testing.assert_allclose(clf.mean_, V[0].mean(0), atol=0.03)  # subsample's mean


@pytest.mark.parametrize("method", METHODS)
def test_small_problems_and_arbitrary_labels(method):
    X, y = _blobs(labels=(-3, 7, 100))
    clf = BodyPartClassifier(method, random_state=0).fit(X, y)
    assert clf.n_train_ == len(X)  # fewer than max_train: all used
    np.testing.assert_array_equal(clf.classes_, [-3, 7, 100])
    np.testing.assert_array_equal(clf.predict(X)[0], y)
    X2, y2 = _blobs(n=40, labels=(4, 9))  # binary
    P = BodyPartClassifier(method, random_state=0).fit(X2, y2).predict_proba(X2)
    assert P.shape == (40, 2)
    np.testing.assert_allclose(P.sum(1), 1.0, atol=1e-12)
    empty = clf.predict_proba(np.empty((0, 3)))
    assert empty.shape == (0, 3)
    assert sum(partition(clf, np.empty((0, 3))).counts) == 0


def test_svc_with_two_points_in_a_class():
    X, y = _blobs(n=60)
    X, y = np.vstack([X, [[0.3, 0, 1], [0.31, 0, 1]]]), np.append(y, [5, 5])
    clf = BodyPartClassifier("svc", random_state=0).fit(X, y)  # 2 folds for Platt
    assert clf.predict(X)[0].shape == (62,)


def test_params():
    clf = BodyPartClassifier("logistic", C=3.0, max_train=50, random_state=4)
    assert clf.get_params() == {"method": "logistic", "C": 3.0, "max_train": 50, "random_state": 4}
    assert clf.set_params(C=5.0) is clf and clf.C == 5.0
    assert "logistic" in repr(clf)
    assert BodyPartClassifier().method == "svc"


# -- errors --------------------------------------------------------------------------------
_X, _Y = _blobs()


@pytest.mark.parametrize(
    ("call", "match"),
    [
        (lambda: BodyPartClassifier().fit(_X, np.zeros(len(_X), int)), "at least 2 distinct"),
        (lambda: BodyPartClassifier().fit(_X, _Y[:-1]), "labels must have shape"),
        (lambda: BodyPartClassifier().fit(_X[:, :2], _Y), r"shape \(n, 3\)"),
        (lambda: BodyPartClassifier().fit(_X, _Y.astype(float)), "must be integers"),
        (lambda: BodyPartClassifier().fit(np.where(_X > 1.005, np.nan, _X), _Y), "non-finite"),
        (lambda: BodyPartClassifier().fit(_X, np.append(_Y[:-1], 9)), "≥ 2 points"),
        (lambda: BodyPartClassifier("rbf").fit(_X, _Y), "method must be one of"),
        (lambda: BodyPartClassifier(C=0).fit(_X, _Y), "C must be a positive"),
        (lambda: BodyPartClassifier(max_train=5).fit(_X, _Y), "max_train must be"),
        (lambda: BodyPartClassifier().predict(_X), "not fitted"),
        (lambda: BodyPartClassifier().predict_proba(_X), "not fitted"),
        (lambda: partition(BodyPartClassifier(), _X), "not fitted"),
        (lambda: BodyPartClassifier("logistic").fit(_X, _Y).predict(_X[:, 0]), "shape"),
        (lambda: BodyPartClassifier().set_params(gamma=1), "unknown option"),
    ],
)
def test_errors(call, match):
    with pytest.raises(InputError, match=match) as info:
        call()
    assert "\n" not in str(info.value)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"on_bone": 0.5, "outlier": 0.5}, "0 ≤ outlier < on_bone ≤ 1"),
        ({"on_bone": 1.2}, "0 ≤ outlier < on_bone ≤ 1"),
        ({"outlier": -0.1}, "0 ≤ outlier < on_bone ≤ 1"),
        ({"keep_fraction": 0.0}, r"keep_fraction must be in \(0, 1\]"),
        ({"keep_fraction": 1.5}, r"keep_fraction must be in \(0, 1\]"),
        ({"on_bone": float("nan")}, "finite"),
        ({"max_distance": 0.0}, "max_distance must be"),
    ],
)
def test_partition_errors(kwargs, match):
    clf = BodyPartClassifier("logistic").fit(_X, _Y)
    with pytest.raises(InputError, match=match) as info:
        partition(clf, _X, **kwargs)
    assert "\n" not in str(info.value)
    with pytest.raises(InputError, match="must be a BodyPartClassifier"):
        partition(object(), _X)


# -- warm start (the tracker's next-frame fit) -----------------------------------------------
def test_logistic_world_logits_reproduce_the_probabilities(walk, fitted):
    _, V, _ = walk
    clf = fitted("logistic", "parts15")
    z = V[1] @ clf.coef_.T + clf.intercept_
    P = np.exp(z - z.max(1, keepdims=True))
    # same softmax as scikit-learn's on the standardised points: rounding only
    np.testing.assert_allclose(P / P.sum(1, keepdims=True), clf.predict_proba(V[1]), atol=1e-12)


def test_warm_start_reaches_the_same_fit_in_fewer_iterations(walk, fitted):
    # Frame 1 fitted from frame 0's logits vs from zeros (15 parts): fewer Newton steps to
    # the same minimum (both stop at a gradient of 1e-6).
    t, V, _ = walk
    lab = _labels(t, "parts15")
    first = fitted("logistic", "parts15")
    cold = BodyPartClassifier("logistic", random_state=0).fit(V[1], lab)
    warm = BodyPartClassifier("logistic", random_state=0).fit(
        V[1], lab, coef_init=first.coef_, intercept_init=first.intercept_
    )
    assert warm.model_.n_iter_[0] < cold.model_.n_iter_[0] / 2
    Pc, Pw = cold.predict_proba(V[1]), warm.predict_proba(V[1])
    assert np.mean(Pc.argmax(1) == Pw.argmax(1)) > 0.99
    assert np.abs(Pc - Pw).mean() < 0.01


@pytest.mark.parametrize(
    ("method", "coef", "intercept", "match"),
    [
        ("svc", np.zeros((3, 3)), np.zeros(3), "applies to method 'logistic' only"),
        ("logistic", np.zeros((2, 3)), np.zeros(2), r"shapes \(3, 3\) and \(3,\)"),
        ("logistic", np.full((3, 3), np.nan), np.zeros(3), "must be finite"),
        ("logistic", "a", np.zeros(3), "must be float arrays"),
    ],
)
def test_warm_start_errors(method, coef, intercept, match):
    with pytest.raises(InputError, match=match) as info:
        BodyPartClassifier(method).fit(_X, _Y, coef_init=coef, intercept_init=intercept)
    assert "\n" not in str(info.value)


# -- the logistic fit (Newton's method) ---------------------------------------------------------
def _softmax_problem(seed=0, n=400, K=4):
    rng = np.random.default_rng(seed)
    centres = rng.normal(size=(K, 3))
    y = rng.integers(0, K, n)
    Z = centres[y] + 0.8 * rng.normal(size=(n, 3))  # overlapping classes: a finite optimum
    return Z, y.astype(np.int64), K


def test_pair_products_are_the_broadcast_products():
    P, Q = np.random.default_rng(2).random((2, 50, 7))
    assert np.array_equal(pair_products(P, P), (P[:, :, None] * P[:, None, :]).reshape(50, -1))
    assert np.array_equal(pair_products(P, Q), (P[:, :, None] * Q[:, None, :]).reshape(50, -1))


def test_softmax_derivatives_match_finite_differences():
    Z, y, K = _softmax_problem()
    n = len(Z)
    Zt = np.hstack([Z, np.ones((n, 1))])
    ZZ = (Zt[:, :, None] * Zt[:, None, :]).reshape(n, -1)
    Wb = np.random.default_rng(1).normal(size=(K, 4))
    l2 = 0.3
    f, g, P = softmax_gradient(Wb, Z, y, l2, Zt)
    H = softmax_hessian(P, ZZ, l2)
    assert f == pytest.approx(softmax_loss(Wb, Z, y, l2), rel=1e-13)
    h = 1e-6
    for t in range(Wb.size):
        e = np.zeros(Wb.size)
        e[t] = h
        e = e.reshape(Wb.shape)
        fp, gp, _ = softmax_gradient(Wb + e, Z, y, l2, Zt)
        fm, gm, _ = softmax_gradient(Wb - e, Z, y, l2, Zt)
        assert (fp - fm) / (2 * h) == pytest.approx(g.ravel()[t], abs=1e-8)
        fd = (gp - gm).ravel() / (2 * h)
        np.testing.assert_allclose(fd, H.reshape(Wb.size, -1)[:, t], atol=1e-8)


def test_softmax_fit_reaches_scikit_learns_optimum():
    # scikit-learn's L-BFGS run to a tight tolerance: the same minimum (it still stops on
    # its loss's relative decrease, 64 ε: probabilities to a few 1e-6)
    from sklearn.linear_model import LogisticRegression

    Z, y, K = _softmax_problem(2)
    ours = SoftmaxRegression(10.0, K).fit(Z, y)
    ref = LogisticRegression(C=10.0, tol=1e-12, max_iter=100_000).fit(Z, y)
    np.testing.assert_allclose(ours.predict_proba(Z), ref.predict_proba(Z), atol=5e-6)
    # from a start near the optimum (the tracker's last frame): fewer steps, same minimum
    warm = SoftmaxRegression(10.0, K).fit(Z, y, (1.05 * ours.coef_, ours.intercept_ + 0.1))
    assert warm.n_iter_[0] < ours.n_iter_[0]
    np.testing.assert_allclose(warm.predict_proba(Z), ours.predict_proba(Z), atol=5e-6)
