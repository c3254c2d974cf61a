"""The registry of methods: every registered variant is a distinct configuration, every
option of every method is checked against its constraint, and ``patch_paper`` minimises
the paper's energy with the paper's coefficients."""

import dataclasses
import importlib
import itertools

import numpy as np
import pytest

from meshmocap._validate import Boolean, Interval, Names, Options, Strings, describe
from meshmocap.errors import InputError
from meshmocap.trackers.patch.energy import energy_terms, paper_terms, total_energy
from meshmocap.trackers.patch.options import PAPER, PatchOptions
from meshmocap.trackers.patch.solver import System, normal_pattern
from meshmocap.trackers.patch.terms import Correspondences, FrameData, Iterate
from meshmocap.trackers.registry import (
    METHODS,
    PATCH_ABLATIONS,
    make_tracker,
    method_options,
    resolved_options,
)


def _configuration(method: str) -> tuple:
    """What a method runs: its tracker class and every field of its resolved options."""
    module, cls, _, _ = METHODS[method]
    return (module, cls, dataclasses.astuple(resolved_options(method)))


def test_no_two_registered_methods_resolve_to_the_same_configuration():
    """A variant that equals another (e.g. fixed options that all equal the defaults) is a
    name without a method: the bench's tables would report one configuration twice."""
    configs = {m: _configuration(m) for m in METHODS}
    same = [(a, b) for a, b in itertools.combinations(METHODS, 2) if configs[a] == configs[b]]
    assert same == []


def test_the_check_sees_a_variant_that_repeats_the_defaults(monkeypatch):
    """The check above fails on a variant whose fixed options are all defaults."""
    spec = METHODS["patch"][:3]
    monkeypatch.setitem(METHODS, "patch_same", (*spec, {"max_iter": PatchOptions().max_iter}))
    assert _configuration("patch_same") == _configuration("patch")


def test_patch_paper_is_eq1_and_the_svm_alone():
    """``patch_paper``: the three terms of Eq. (1) with the paper's weights (λd = 10,
    λr = 1, λb = 1), the linear SVM of §III-B, and none of the extensions."""
    opts = resolved_options("patch_paper")
    terms = energy_terms(opts)
    assert [(t.name, t.weight) for t in terms] == [
        ("data", 10.0),
        ("rigidity", 1.0),
        ("bone", 1.0),
    ]
    assert opts.classifier == "svc" and (opts.on_bone, opts.outlier) == (0.9, 0.5)
    assert opts.joint_readout == "skeleton" and opts.prediction == "none"
    assert opts.fast_iter_scale == 1.0 and opts.coarse_iter == 0 and opts.joint_rigidity == 1.0
    assert opts == PatchOptions(**PAPER)
    # the default tracker has extension terms the paper does not
    names = {t.name for t in energy_terms(resolved_options("patch"))}
    assert names == {"data", "rigidity", "bone", "reverse", "length"}
    assert set(PATCH_ABLATIONS) <= set(METHODS)


def test_resolved_options_rejects_an_unknown_method():
    with pytest.raises(InputError, match="method must be one of"):
        resolved_options("nope")


def _options_class(method: str) -> type:
    module, _, opts_cls, _ = METHODS[method]
    return getattr(importlib.import_module(module), opts_cls)


def _invalid(constraint):
    """A value that breaks ``constraint`` (of a tuple: all of them)."""
    if isinstance(constraint, tuple):
        return _invalid(next(c for c in constraint if c is not None))
    if isinstance(constraint, Interval):
        if constraint.low is not None:
            left = constraint.closed in ("left", "both")
            return constraint.low - 1 if left else constraint.low
        return constraint.high + 1
    return {Options: "not-an-option", Boolean: "yes", Names: ("not-a-term",), Strings: "abc"}[
        type(constraint)
    ]


@pytest.mark.parametrize("method", sorted(METHODS))
def test_every_option_of_every_method_is_checked_with_a_one_line_error(method):
    """Each options class states a constraint for every option (a new option without one
    fails here), and for every option a method takes, an invalid value is refused by
    ``make_tracker`` in one line that names the method, the option, its constraint and the
    value found (options a variant fixes cannot be given)."""
    cls = _options_class(method)
    table = cls.constraints
    assert {f.name for f in dataclasses.fields(cls)} == set(table), cls.__name__
    for option in method_options(method):
        bad = _invalid(table[option])
        with pytest.raises(InputError) as info:
            make_tracker(method, **{option: bad})
        message = str(info.value)
        assert "\n" not in message
        assert f"method {method!r}" in message and f"{cls.__name__}: {option} must be" in message
        assert describe(table[option]) in message and f"found {bad!r}" in message, message


@pytest.fixture(scope="module")
def patch_iterate(patch_problem):
    """The shared patch problem (conftest) as the terms' inputs."""
    m, mom, R, c, X, (patch, v, y, w) = patch_problem
    corr = Correspondences(patch, v, w, y, np.zeros_like(y))
    none = np.zeros(0, int)
    fd = FrameData(m, mom, y, y, [], None, X, none.reshape(0, 2), none, none, none, 0.01, 0.0)
    Rl = R[m.labels]
    V = np.einsum("nij,nj->ni", Rl, m.V0 - m.centres0[m.labels]) + c[m.labels]
    N = np.einsum("nij,nj->ni", Rl, m.N0)
    return normal_pattern(m, 15), Iterate(fd, R, c, X, V, N, corr)


@pytest.mark.parametrize(
    ("method", "expected"),
    [("patch_paper", (10.0, 1.0, 1.0)), ("patch", (10.0, 10.0, 100.0))],
)
def test_the_paper_row_minimises_the_papers_coefficients(patch_iterate, method, expected):
    """The coefficient each term of Eq. (1) actually puts in the normal equations and in the
    total energy: ``patch_paper`` λd : λr : λb = 10 : 1 : 1 (the paper's, §III-C), our
    ``patch`` 10 : 10 : 100 (its rigidity and bone scales)."""
    pattern, it = patch_iterate
    terms = paper_terms(resolved_options(method))
    values = {}
    for t, coef in zip(terms, expected, strict=True):
        sys, unit = System.empty(pattern), System.empty(pattern)
        values[t.name] = t.add(sys, it)
        scaled = "scale" in {f.name for f in dataclasses.fields(t)}
        unit_term = dataclasses.replace(t, weight=1.0, **({"scale": 1.0} if scaled else {}))
        assert unit_term.add(unit, it) == pytest.approx(values[t.name], rel=1e-12)
        used = np.linalg.lstsq(unit.g[:, None], sys.g, rcond=None)[0][0]  # sys = coef × unit
        assert used == pytest.approx(coef, rel=1e-9), t.name
        np.testing.assert_allclose(
            sys.D, coef * unit.D, rtol=1e-9, atol=1e-12 * np.abs(sys.D).max()
        )
    total = total_energy(terms, values)
    assert total == pytest.approx(
        sum(c * values[t.name] for t, c in zip(terms, expected, strict=True)), rel=1e-12
    )
