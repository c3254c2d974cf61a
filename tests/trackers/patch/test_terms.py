"""The patch tracker's energy as a list of frozen terms (trackers/patch/terms.py,
energy.py): one system from the list, the total from the same list, and the total's
gradient against float64 finite differences."""

import numpy as np
import pytest

from meshmocap.body.template import load_template
from meshmocap.geometry.rotations import so3_exp
from meshmocap.trackers.patch.energy import assemble, energy_terms, total_energy
from meshmocap.trackers.patch.options import PatchOptions
from meshmocap.trackers.patch.solver import System, normal_pattern
from meshmocap.trackers.patch.terms import (
    BoneTerm,
    Correspondences,
    DataTerm,
    FrameData,
    Iterate,
    LengthTerm,
    RigidityTerm,
    TemporalTerm,
)

RNG = np.random.default_rng(3)


@pytest.fixture(scope="module")
def setup(patch_problem):
    """The shared problem (conftest) with its correspondences, a length prior on five
    joint pairs held 5 % longer than at rest, and a temporal prediction 1 cm off."""
    m, mom, R, c, X, (patch, v, y, w) = patch_problem
    X0 = load_template("neutral_5k").eval_skeleton.rest_positions
    corr = Correspondences(patch, v, w, y, np.zeros_like(y))
    pairs = np.array([[1, 0], [2, 1], [3, 2], [4, 0], [5, 4]])
    fd = FrameData(
        model=m,
        moments=mom,
        Y=y,
        NY=np.zeros_like(y),
        cameras=[],
        frame=None,
        X_hat=X0 + RNG.normal(scale=0.01, size=(15, 3)),
        pairs=pairs,
        lengths=np.linalg.norm(X0[pairs[:, 0]] - X0[pairs[:, 1]], axis=1) * 1.05,
        reverse_sample=np.arange(0, len(m.V0), 10),
        cover_sample=np.arange(0, len(m.V0), 10),
        cover_radius=0.01,
        normal_cos=0.0,
    )
    return m, fd, corr, R, c, X


def _iterate(fd, corr, R, c, X):
    m = fd.model
    Rl = R[m.labels]
    V = np.einsum("nij,nj->ni", Rl, m.V0 - m.centres0[m.labels]) + c[m.labels]
    return Iterate(fd, R, c, X, V, np.einsum("nij,nj->ni", Rl, m.N0), corr)


#: Terms whose Gauss–Newton rows are exact derivatives at fixed correspondences (the
#: reverse and silhouette terms re-pick their targets and Cauchy weights per iteration).
TERMS = (
    DataTerm(10.0),
    RigidityTerm(1.0, 10.0),
    BoneTerm(1.0, 100.0),
    LengthTerm(100.0),
    TemporalTerm(1.0),
)


def test_the_system_of_a_term_list_is_the_sum_of_its_terms(setup):
    """Terms only add to the system: assembling the list equals adding each term's own
    system, and each value enters the total once, times its coefficient."""
    m, fd, corr, R, c, X = setup
    it = _iterate(fd, corr, R, c, X)
    pattern = normal_pattern(m, 15)
    together = System.empty(pattern)
    values = assemble(TERMS, together, it)
    parts = [System.empty(pattern) for _ in TERMS]
    for t, s in zip(TERMS, parts, strict=True):
        assert t.add(s, it) == pytest.approx(values[t.name], rel=1e-12)
    for field in ("D", "O", "PJ", "JJ", "g"):
        expected = sum(getattr(s, field) for s in parts)
        assert np.allclose(getattr(together, field), expected, rtol=1e-12, atol=1e-15), field
    coef = {"data": 10.0, "rigidity": 10.0, "bone": 100.0, "length": 100.0, "temporal": 1.0}
    assert total_energy(TERMS, values) == pytest.approx(
        sum(coef[k] * v for k, v in values.items()), rel=1e-12
    )


def test_the_total_energy_gradient_matches_finite_differences(setup):
    """The system's gradient is half the gradient of :func:`total_energy` (E = Σ r², g =
    Jᵀ r): the weight a term puts in the system is the one its value has in the total."""
    m, fd, corr, R, c, X = setup
    sys = System.empty(normal_pattern(m, 15))
    assemble(TERMS, sys, _iterate(fd, corr, R, c, X))

    def energy(delta):
        d = delta[: 6 * m.P].reshape(m.P, 6)
        it = _iterate(
            fd, corr, so3_exp(d[:, :3]) @ R, c + d[:, 3:], X + delta[6 * m.P :].reshape(-1, 3)
        )
        scratch = System.empty(normal_pattern(m, 15))
        return total_energy(TERMS, assemble(TERMS, scratch, it))

    n = 6 * m.P + 45
    h = 1e-6
    for i in [*RNG.choice(6 * m.P, 30, replace=False), *range(6 * m.P, n, 4)]:
        d = np.zeros(n)
        d[i] = h
        fd_i = (energy(d) - energy(-d)) / (2 * h)
        assert fd_i == pytest.approx(2 * sys.g[i], rel=1e-5, abs=1e-6), i


def test_zero_weights_leave_extensions_out():
    names = lambda o: [t.name for t in energy_terms(o)]  # noqa: E731
    assert names(PatchOptions()) == ["data", "rigidity", "bone", "reverse", "length"]
    both = PatchOptions(lambda_reverse=0.0, lambda_length=0.0, lambda_temporal=2.0)
    assert names(both) == ["data", "rigidity", "bone", "temporal"]
    assert names(PatchOptions(lambda_silhouette=1.0))[-1] == "silhouette"


@pytest.mark.parametrize("name", ["lambda_data", "lambda_bone", "lambda_length"])
def test_negative_weights_are_rejected(name):
    from meshmocap.errors import InputError

    with pytest.raises(InputError, match=f"{name} must be a number ≥ 0, found -1.0"):
        PatchOptions(**{name: -1.0})
