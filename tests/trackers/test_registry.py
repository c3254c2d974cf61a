"""The registry of methods: every registered variant is a distinct configuration."""

import dataclasses
import itertools

import pytest

from meshmocap.errors import InputError
from meshmocap.trackers.patch.energy import energy_terms
from meshmocap.trackers.patch.options import PAPER, PatchOptions
from meshmocap.trackers.registry import METHODS, PATCH_ABLATIONS, resolved_options


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
