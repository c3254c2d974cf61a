"""The cage tracker's energy as a list of terms, and its variants (trackers/cage/terms.py)."""

import importlib
from dataclasses import asdict

import numpy as np
import pytest

from meshmocap.errors import InputError
from meshmocap.geometry.rotations import so3_exp
from meshmocap.trackers.cage.energy import Articulation, HullCoverage
from meshmocap.trackers.cage.options import CageOptions
from meshmocap.trackers.cage.terms import (
    ALL_TERMS,
    PAPER_TERMS,
    AnchorTerm,
    ArticulationTerm,
    CoverageTerm,
    DistanceTerm,
    VarianceTerm,
)
from meshmocap.trackers.registry import MANIFOLD_METHODS, METHODS


class _Field:
    """A signed distance to the unit sphere (negative inside)."""

    def value_and_gradient(self, P):
        n = np.linalg.norm(P, axis=1)
        return n - 1.0, P / n[:, None]


def test_distance_term_weighs_inside_margin_and_cap():
    P = np.array([[0.5, 0, 0], [1.02, 0, 0], [1.2, 0, 0], [0, 2.0, 0]])
    w = np.array([1.0, 1.0, 1.0, 0.5])
    r, g = DistanceTerm(
        _Field(), w, inside_weight=0.04, outside_margin=0.0, outside_cap=0.0
    ).residuals(P)
    np.testing.assert_allclose(r, [0.2 * -0.5, 0.02, 0.2, 0.5], atol=1e-15)  # √0.04 inside
    np.testing.assert_allclose(g[1], [1.0, 0, 0])
    t = DistanceTerm(_Field(), w, inside_weight=1.0, outside_margin=0.05, outside_cap=0.5)
    r, g = t.residuals(P)
    # outside: beyond the margin only, and nothing past the cap (a hole in the hull)
    np.testing.assert_allclose(r, [-0.5, 0.0, 0.15, 0.0], atol=1e-15)
    assert not g[3].any()
    r, _ = t.residuals(P[2:], slice(2, None))  # a subset of the points: their weights
    np.testing.assert_allclose(r, [0.15, 0.0], atol=1e-15)


def test_coverage_term_is_its_weighted_mean():
    rng = np.random.default_rng(0)
    cov = HullCoverage(rng.normal(size=(50, 3)), margin=0.1)
    P = rng.normal(size=(20, 3))
    term = CoverageTerm(cov, 0.3, name="coverage", local=False)
    r, _ = term.residuals(P)
    rho2 = cov.residuals(P)[0] ** 2
    assert abs(0.5 * r @ r - 0.3 / 50 * 0.5 * rho2.sum()) < 1e-15
    assert abs(term.mean_squared(P) - rho2.sum() / 50) < 1e-15


def test_configuration_terms_gradients_match_finite_differences():
    rng = np.random.default_rng(1)
    # variance: λ log σ²(x) through a smooth σ²; gradient w.r.t. x by the chain rule
    vt = VarianceTerm(2e-3, 1e-4)
    A = rng.normal(size=(3, 3))

    def var(x):
        return float(x @ A @ A.T @ x), 2 * A @ A.T @ x

    x, h = rng.normal(size=3), 1e-6
    g, H = vt.rows(vt.variance(var(x)[0]), var(x)[1])
    d = rng.normal(size=3)
    fd = (vt.value(var(x + h * d)[0]) - vt.value(var(x - h * d)[0])) / (2 * h)
    assert abs(g @ d - fd) <= 1e-6 * max(1e-3, abs(fd))
    assert np.all(np.linalg.eigvalsh(H) > -1e-15)  # Gauss–Newton: positive semi-definite
    # anchor and articulation along each quad's (dc, ω): c + dc, exp(ω) R
    n = 20
    Rq = so3_exp(rng.normal(scale=0.3, size=(n, 3)))
    y = np.stack([rng.normal(size=(n, 3)), Rq[:, :, 0], Rq[:, :, 1]], axis=1).reshape(-1)
    anchor = y + 0.05 * rng.normal(size=y.shape)
    at = AnchorTerm(3.0)

    def moved(y, step):
        Y, dq = y.reshape(-1, 3, 3), step.reshape(-1, 6)
        R = so3_exp(dq[:, 3:])
        return np.stack(
            [
                Y[:, 0] + dq[:, :3],
                np.einsum("kij,kj->ki", R, Y[:, 1]),
                np.einsum("kij,kj->ki", R, Y[:, 2]),
            ],
            axis=1,
        ).reshape(-1)

    grad, H = np.zeros(6 * n), np.zeros((6 * n, 6 * n))
    at.add_rows(grad, H, y, anchor)
    d = rng.normal(size=6 * n)
    fd = (at.value(moved(y, h * d), anchor) - at.value(moved(y, -h * d), anchor)) / (2 * h)
    assert abs(grad @ d - fd) <= 1e-6 * max(1e-3, abs(fd))
    # soft joints: a chain of 20 joints, a quad each, the last joint with a second (rigid)
    c0 = np.cumsum(rng.normal(scale=0.1, size=(21, 3)), axis=0)
    R0 = so3_exp(rng.normal(scale=0.2, size=(21, 3)))
    art = Articulation(c0, R0, np.r_[np.arange(20), 19], c0[:20] + 0.02, np.arange(-1, 19))
    jt = ArticulationTerm(art, 10.0)
    c, R = c0 + 0.01 * rng.normal(size=c0.shape), R0 @ so3_exp(0.05 * rng.normal(size=(21, 3)))
    c[0], R[0] = 0.0, np.eye(3)
    grad, H = np.zeros(6 * n), np.zeros((6 * n, 6 * n))
    jt.add_rows(grad, H, c, R)

    def value(step):
        dq = step.reshape(-1, 6)
        return jt.value(
            c + np.r_[np.zeros((1, 3)), dq[:, :3]],
            np.concatenate([R[:1], so3_exp(dq[:, 3:]) @ R[1:]]),
        )

    fd = (value(h * d) - value(-h * d)) / (2 * h)
    assert abs(grad @ d - fd) <= 1e-6 * max(1e-3, abs(fd))


def test_options_hold_a_term_list():
    assert CageOptions().terms == ALL_TERMS
    o = CageOptions(terms=["variance", "distance"])  # any order, from JSON lists too
    assert o.terms == PAPER_TERMS
    with pytest.raises(InputError, match="terms must be one of"):
        CageOptions(terms=("distance", "smoothness"))
    with pytest.raises(InputError, match="must hold 'distance'"):
        CageOptions(terms=("variance",))


def test_every_cage_variant_is_its_own_configuration_and_cage_paper_the_papers_terms():
    seen = {}
    for m in MANIFOLD_METHODS:
        module, _, options, fixed = METHODS[m]
        o = getattr(importlib.import_module(module), options)(**fixed)
        key = repr(asdict(o))
        assert key not in seen, f"{m} and {seen.get(key)} resolve to the same configuration"
        seen[key] = m
    paper = CageOptions(**METHODS["cage_paper"][3])
    assert paper.terms == PAPER_TERMS == ("distance", "variance")
    assert (paper.surface, paper.joints, paper.body) == ("green", "green", "template")
    assert "silhouette" not in CageOptions(**METHODS["cage_nosil"][3]).terms
