"""The cage tracker's energy as a list of frozen terms with one interface
(trackers/cage/terms.py, energy.py), and its variants."""

import dataclasses
import importlib
from dataclasses import asdict

import numpy as np
import pytest

from meshmocap.errors import InputError
from meshmocap.geometry.rotations import so3_exp
from meshmocap.trackers.cage.energy import assemble, energy_terms, stage_terms, total_energy
from meshmocap.trackers.cage.options import CageOptions
from meshmocap.trackers.cage.residuals import Articulation, HullCoverage
from meshmocap.trackers.cage.terms import (
    ALL_TERMS,
    PAPER_TERMS,
    AnchorTerm,
    ArticulationTerm,
    CoverageTerm,
    DistanceTerm,
    FrameData,
    Iterate,
    System,
    VarianceTerm,
)
from meshmocap.trackers.registry import MANIFOLD_METHODS, METHODS


class _Field:
    """A signed distance to the unit sphere (negative inside)."""

    def value_and_gradient(self, P):
        n = np.linalg.norm(P, axis=1)
        return n - 1.0, P / n[:, None]


def _frame(w=None, **kw):
    return FrameData(
        field=_Field(), point_weights=w, noise=kw.pop("noise", 0.0), articulation=None, **kw
    )


def test_distance_term_weighs_inside_margin_and_cap():
    P = np.array([[0.5, 0, 0], [1.02, 0, 0], [1.2, 0, 0], [0, 2.0, 0]])
    fd = _frame(np.array([1.0, 1.0, 1.0, 0.5]))
    r, g = DistanceTerm(inside_weight=0.04).residuals(Iterate(fd, P))
    np.testing.assert_allclose(r, [0.2 * -0.5, 0.02, 0.2, 0.5], atol=1e-15)  # √0.04 inside
    np.testing.assert_allclose(g[1], [1.0, 0, 0])
    t = DistanceTerm(inside_weight=1.0, outside_margin=0.05, outside_cap=0.5)
    r, g = t.residuals(Iterate(fd, P))
    # outside: beyond the margin only, and nothing past the cap (a hole in the hull)
    np.testing.assert_allclose(r, [-0.5, 0.0, 0.15, 0.0], atol=1e-15)
    assert not g[3].any()
    r, _ = t.residuals(Iterate(fd, P[2:], slice(2, None)))  # a subset of the points
    np.testing.assert_allclose(r, [0.15, 0.0], atol=1e-15)
    sys = System.empty(0)
    value = t.add(sys, Iterate(fd, P))
    assert value == pytest.approx(0.5 * (0.25 + 0.15**2), rel=1e-12) and len(sys.r) == 1


def test_coverage_term_is_its_weighted_mean_and_nothing_without_samples():
    rng = np.random.default_rng(0)
    cov = HullCoverage(rng.normal(size=(50, 3)), margin=0.1)
    P = rng.normal(size=(20, 3))
    sys = System.empty(0)
    value = CoverageTerm(0.3).add(sys, Iterate(_frame(hull=cov), P))
    rho2 = cov.residuals(P)[0] ** 2
    assert abs(value - 0.5 * rho2.sum() / 50) < 1e-15
    r, _ = sys.point_rows()
    assert abs(0.5 * r @ r - 0.3 * value) < 1e-15  # the rows carry the coefficient
    empty = System.empty(0)
    assert CoverageTerm(0.3).add(empty, Iterate(_frame(), P)) == 0.0 and not empty.r


def test_parameter_terms_gradients_match_finite_differences():
    """Each term's rows are the gradient of coefficient × value (Gauss–Newton matrices
    positive semi-definite)."""
    rng = np.random.default_rng(1)
    h = 1e-6
    # variance: λ log σ²(x) through a smooth σ²; gradient w.r.t. x by the chain rule
    vt = VarianceTerm(2e-3)
    A = rng.normal(size=(3, 3))
    fd0 = _frame(noise=1e-4)

    def at(x):
        return Iterate(fd0, np.zeros((1, 3)), var=float(x @ A @ A.T @ x), dvar=2 * A @ A.T @ x)

    x = rng.normal(size=3)
    sys = System.empty(3)
    vt.add(sys, at(x))
    d = rng.normal(size=3)
    scratch = System.empty(3)
    fd = (
        vt.coefficient * (vt.add(scratch, at(x + h * d)) - vt.add(scratch, at(x - h * d))) / (2 * h)
    )
    assert abs(sys.grad @ d - fd) <= 1e-6 * max(1e-3, abs(fd))
    assert np.all(np.linalg.eigvalsh(sys.H) > -1e-15)  # Gauss–Newton: positive semi-definite
    # anchor and articulation along each quad's (dc, ω): c + dc, exp(ω) R
    n = 20
    Rq = so3_exp(rng.normal(scale=0.3, size=(n, 3)))
    y = np.stack([rng.normal(size=(n, 3)), Rq[:, :, 0], Rq[:, :, 1]], axis=1).reshape(-1)
    anchor = y + 0.05 * rng.normal(size=y.shape)
    at_ = AnchorTerm(3.0)

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

    def anchored(y):
        return Iterate(fd0, np.zeros((1, 3)), y=y, anchor=anchor)

    sys = System.empty(6 * n + 6)
    at_.add(sys, anchored(y))
    d = rng.normal(size=6 * n)
    e = [at_.add(System.empty(6 * n + 6), anchored(moved(y, s * h * d))) for s in (1, -1)]
    fd = at_.coefficient * (e[0] - e[1]) / (2 * h)
    assert abs(sys.grad[: 6 * n] @ d - fd) <= 1e-6 * max(1e-3, abs(fd))
    # soft joints: a chain of 20 joints, a quad each, the last joint with a second (rigid)
    c0 = np.cumsum(rng.normal(scale=0.1, size=(21, 3)), axis=0)
    R0 = so3_exp(rng.normal(scale=0.2, size=(21, 3)))
    art = Articulation(c0, R0, np.r_[np.arange(20), 19], c0[:20] + 0.02, np.arange(-1, 19))
    fdj = dataclasses.replace(fd0, articulation=art)
    jt = ArticulationTerm(10.0)
    c, R = c0 + 0.01 * rng.normal(size=c0.shape), R0 @ so3_exp(0.05 * rng.normal(size=(21, 3)))
    c[0], R[0] = 0.0, np.eye(3)
    sys = System.empty(6 * n + 6)
    jt.add(sys, Iterate(fdj, np.zeros((1, 3)), quads=(c, R)))

    def value(step):
        dq = step.reshape(-1, 6)
        quads = (
            c + np.r_[np.zeros((1, 3)), dq[:, :3]],
            np.concatenate([R[:1], so3_exp(dq[:, 3:]) @ R[1:]]),
        )
        return jt.coefficient * jt.add(System.empty(6 * n + 6), Iterate(fdj, c, quads=quads))

    d = rng.normal(size=6 * n)
    fd = (value(h * d) - value(-h * d)) / (2 * h)
    assert abs(sys.grad[: 6 * n] @ d - fd) <= 1e-6 * max(1e-3, abs(fd))
    # without their inputs (no anchor: off the manifold; no quads) they add nothing
    empty = System.empty(6 * n + 6)
    assert at_.add(empty, Iterate(fd0, c)) == 0.0 and jt.add(empty, Iterate(fdj, c)) == 0.0
    assert not empty.grad.any() and not empty.H.any()


def test_the_energy_is_the_term_list_and_its_total_the_sum_over_it():
    """A term is on when it is in ``CageOptions.terms``; the list keeps its order, each
    term takes its weight from its option, and a problem's energy is Σ coefficient ×
    value over the list's terms of that problem."""
    o = CageOptions(variance_weight=2e-5, coverage_weight=0.4, anchor_weight=1e-4)
    terms = energy_terms(o)
    assert tuple(t.name for t in terms) == ALL_TERMS
    weights = {t.name: t.coefficient for t in terms}
    assert weights == {
        "distance": 1.0,
        "variance": 2e-5,
        "coverage": 0.4,
        "silhouette": o.silhouette_weight,
        "anchor": 1e-4,
        "articulation": o.articulation,
    }
    paper = energy_terms(CageOptions(terms=PAPER_TERMS))
    assert [type(t) for t in paper] == [DistanceTerm, VarianceTerm]
    assert [t.name for t in stage_terms(terms, "local")] == [
        "distance",
        "silhouette",
        "anchor",
        "articulation",
    ]
    assert [t.name for t in stage_terms(terms, "shape")] == [
        "distance",
        "variance",
        "coverage",
        "silhouette",
    ]
    rng = np.random.default_rng(2)
    P = rng.normal(size=(30, 3))
    fd = _frame(np.full(30, 0.2), noise=1e-4, hull=HullCoverage(rng.normal(size=(40, 3)), 0.05))
    shape = stage_terms(terms, "shape")
    sys = System.empty(2)
    values = assemble(shape, sys, Iterate(fd, P, var=0.3, dvar=np.array([0.1, -0.2])))
    assert values["silhouette"] == 0.0  # no silhouettes this frame: nothing
    r, _ = sys.point_rows()
    expected = 0.5 * r @ r + 2e-5 * np.log(0.3 + 1e-4)
    assert total_energy(shape, values) == pytest.approx(expected, rel=1e-12)


def test_options_hold_a_term_list():
    assert CageOptions().terms == ALL_TERMS
    o = CageOptions(terms=["variance", "distance"])  # any order, from JSON lists too
    assert o.terms == PAPER_TERMS
    with pytest.raises(InputError, match=r"terms must be distinct names from \[.*found"):
        CageOptions(terms=("distance", "smoothness"))
    with pytest.raises(InputError, match=r"holding \['distance'\], found \('variance',\)"):
        CageOptions(terms=("variance",))
    with pytest.raises(InputError, match="terms must be"):
        CageOptions(terms=("distance", "distance"))
    with pytest.raises(InputError, match="variance_weight must be a number > 0, found 0"):
        CageOptions(variance_weight=0)  # a term is off by leaving it out of the list


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
