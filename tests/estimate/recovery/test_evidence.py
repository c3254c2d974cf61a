"""The rule that flags a limb lost from a frame's evidence: thresholds per measure, shipped
as data, fitted to flag bad frames within a budget of good ones."""

import numpy as np
import pytest

from meshmocap.errors import FormatError, InputError
from meshmocap.estimate.recovery.evidence import (
    EVIDENCE,
    LostRule,
    fit_rule,
    lost_limbs,
    lost_reasons,
    shipped_rule,
)
from meshmocap.estimate.recovery.quality import LIMB_PARTS


def _evidence(**limbs) -> np.ndarray:
    """(L, E) zeros with the given limbs' measures set: ``left_arm={"outside": 0.5}``."""
    E = np.zeros((len(LIMB_PARTS), len(EVIDENCE)))
    for limb, measures in limbs.items():
        for m, v in measures.items():
            E[list(LIMB_PARTS).index(limb), EVIDENCE.index(m)] = v
    return E


def test_a_limb_is_lost_when_a_measure_passes_its_threshold():
    rule = LostRule((0.4, 0.5, 0.1, 0.5, np.inf, 0.2))
    E = _evidence(left_arm={"outside": 0.45}, right_leg={"speed": 0.25, "residual": 9.0})
    assert lost_limbs(E, rule) == ("left_arm", "right_leg")
    why = lost_reasons(E, rule)
    assert why["left_arm"] == "45% outside the observations"
    assert why["right_leg"] == "moved 250 mm since the last frame"  # residual: never flags
    assert lost_limbs(_evidence(head={"outside": 0.4}), rule) == ()  # not past it
    frames = np.stack([E, _evidence(), _evidence(torso={"unseen": 1.0})])
    assert rule.flags(frames).tolist() == [True, False, True]
    with pytest.raises(InputError, match="expected 6 thresholds"):
        LostRule((0.1, 0.2))


def test_the_rule_round_trips_and_the_shipped_one_loads(tmp_path):
    rule = LostRule((0.3, np.inf, 0.05, 0.5, 0.04, 0.12))
    rule.write(tmp_path / "r.json", note="test")
    assert LostRule.read(tmp_path / "r.json") == rule
    (tmp_path / "bad.json").write_text('{"limits": {}}')
    with pytest.raises(FormatError, match=r"bad\.json is not a rule file"):
        LostRule.read(tmp_path / "bad.json")
    shipped = shipped_rule()
    assert len(shipped.thresholds) == len(EVIDENCE) and any(np.isfinite(shipped.thresholds))
    assert lost_limbs(_evidence()) == ()  # nothing on a frame without evidence


def test_fit_rule_flags_bad_frames_within_the_budget_of_good_ones():
    rng = np.random.default_rng(0)
    n = 2000
    E = np.abs(rng.normal(0.0, 0.05, (n, len(LIMB_PARTS), len(EVIDENCE))))
    bad = rng.random(n) < 0.1
    k = EVIDENCE.index("speed")
    E[bad, 2, k] += 0.3  # bad frames: a limb that jumped, and noise on the rest
    rule = fit_rule([E[:1000], E[1000:]], [bad[:1000], bad[1000:]], good_rate=0.02)
    f = rule.flags(E)
    assert np.count_nonzero(f & ~bad) <= 0.02 * np.count_nonzero(~bad)
    assert np.count_nonzero(f & bad) >= 0.95 * np.count_nonzero(bad)
    assert np.isfinite(rule.thresholds[k])
