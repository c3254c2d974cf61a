"""The one damped solve: its rule (λ relative to the diagonal, a floor relative to the
median curvature), bounded retries that end in FitError, and the adaptive λ."""

import numpy as np
import pytest

from meshmocap.errors import FitError
from meshmocap.geometry.levenberg_marquardt import (
    DAMPING,
    LAMBDA_MAX,
    LAMBDA_MIN,
    RETRIES,
    AdaptiveDamping,
    damped_diagonal,
    damped_solve,
    solve_damped,
)

RNG = np.random.default_rng(7)


def test_the_step_solves_the_damped_normal_equations():
    A = RNG.normal(size=(9, 6))
    H, g = A.T @ A, RNG.normal(size=6)
    d = np.diag(H)
    for lam, floor in [(0.0, 0.0), (1e-3, 1e-9), (0.5, 1e-3)]:
        x = damped_solve(H, g, lam=lam, floor=floor)
        M = H + np.diag(lam * d + floor * np.median(d))
        assert np.abs(M @ x + g).max() <= 1e-12 * np.abs(g).max()
    # λ → ∞: a gradient step scaled by the diagonal, x ≈ −g / (λ d)
    x = damped_solve(H, g, lam=1e8, floor=0.0)
    np.testing.assert_allclose(x * 1e8 * d, -g, rtol=1e-6)


def test_an_unconstrained_unknown_stays_at_zero():
    """A zero row and column (nothing observes that unknown, its gradient is zero): the
    floor makes the system solvable and the unknown does not move."""
    A = RNG.normal(size=(8, 4))
    H = np.zeros((5, 5))
    H[:4, :4] = A.T @ A
    g = np.r_[RNG.normal(size=4), 0.0]
    x = damped_solve(H, g, lam=1e-3, floor=1e-9)
    assert x[4] == 0.0 and np.all(np.isfinite(x))
    floor = damped_diagonal(np.diag(H), 0.0, 1e-9)
    assert floor == pytest.approx(np.full(5, 1e-9 * np.median(np.diag(H)[:4])), rel=1e-12)


def test_the_floor_is_numpys_median_of_the_positive_curvatures_to_the_bit():
    """The floor's median is taken by a sort (np.median's overhead was a fifth of a small
    solve): the same number as np.median for odd and even counts, none positive gives 1."""
    for n in (1, 2, 3, 6, 7, 126):
        d = RNG.normal(size=n) * 10.0 ** RNG.uniform(-6, 6, size=n)
        d[0] = abs(d[0])  # at least one positive
        expected = 1e-3 * d + 1e-9 * float(np.median(d[d > 0]))
        assert np.array_equal(damped_diagonal(d, 1e-3, 1e-9), expected)
    assert np.array_equal(damped_diagonal(-np.ones(3), 0.0, 2.0), np.full(3, 2.0))


def test_a_singular_system_is_retried_with_more_damping_then_a_fit_error():
    calls = []

    def singular(add):
        calls.append(add.copy())
        raise np.linalg.LinAlgError("Singular matrix")

    with pytest.raises(FitError, match=r"singular normal equations \(Singular matrix"):
        solve_damped(singular, np.ones(3), lam=1e-3, floor=0.0)
    assert len(calls) == RETRIES + 1
    lams = [c[0] for c in calls]
    np.testing.assert_allclose(lams, 1e-3 * 10.0 ** np.arange(RETRIES + 1), rtol=1e-12)

    def once(add):  # singular without damping, solvable with it: retried, then solved
        if add[0] == 0:
            raise np.linalg.LinAlgError("Singular matrix")
        return np.ones(3) / add[0]

    np.testing.assert_allclose(solve_damped(once, np.ones(3), lam=0.0, floor=0.0), 1 / LAMBDA_MIN)
    # an exactly singular dense system (no floor, λ = 0 and a zero row) and non-finite input
    H = np.diag([1.0, 0.0])
    with pytest.raises(FitError, match="singular"):
        damped_solve(H, np.array([1.0, 1.0]), lam=0.0, floor=0.0, what="test system")
    with pytest.raises(FitError, match="singular test system"):
        damped_solve(np.full((2, 2), np.nan), np.ones(2), lam=0.1, floor=0.0, what="test system")
    with pytest.raises(FitError, match="non-finite"):
        damped_solve(np.eye(2), np.array([np.inf, 0.0]), lam=0.1, floor=0.0)


def test_a_non_finite_step_is_a_fit_error_not_a_nan():
    with pytest.raises(FitError, match="non-finite step"):
        solve_damped(lambda add: np.full(2, np.nan), np.ones(2), lam=1.0, floor=0.0)


def test_adaptive_damping_divides_on_accept_multiplies_on_reject_and_gives_up():
    mu = AdaptiveDamping(1e-6)
    mu.accepted()
    assert mu.lam == pytest.approx(1e-7)
    for _ in range(5):
        mu.accepted()
    assert mu.lam == LAMBDA_MIN  # not below
    mu = AdaptiveDamping(1e-6)
    n = 0
    while mu.rejected():
        n += 1
    assert mu.lam > LAMBDA_MAX and n == 14  # 1e-6 · 10¹⁴ = 1e8 is the last allowed


def test_every_rule_of_the_table_is_a_nonnegative_lambda_and_floor():
    assert {"articulated", "icp", "vertex", "pose_fit", "cage", "patch", "none"} <= set(DAMPING)
    for name, rule in DAMPING.items():
        assert rule.lam >= 0 and rule.floor >= 0, name
