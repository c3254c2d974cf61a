"""The rule that flags a limb lost from a frame's evidence: thresholds per measure, shipped
as data, fitted to flag bad frames within a budget of good ones."""

import numpy as np
import pytest

from meshmocap.errors import FormatError, InputError
from meshmocap.estimate.recovery.evidence import (
    DISAGREE,
    DISAGREEMENT,
    DISPLACED,
    EVIDENCE,
    FITTED,
    START,
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


def test_the_points_a_limb_leaves_unexplained_are_blamed_on_the_limb_outside():
    """An arm turned away leaves its points by the trunk and a leg, which fit themselves:
    the arm standing outside the observations is named, not them; the frame is lost
    either way."""
    rule = LostRule((0.9, np.inf, 0.02, np.inf, np.inf, np.inf))
    arm = {"outside": 0.8, "unexplained": 0.003}
    assert arm["outside"] > DISPLACED
    E = _evidence(left_arm=arm, torso={"unexplained": 0.021}, left_leg={"unexplained": 0.15})
    assert rule.limb_lost(E).tolist() == [True, False, False, False, True, False]
    assert lost_limbs(E, rule) == ("left_arm",) and rule.flags(E[None]).tolist() == [True]
    why = lost_reasons(E, rule)
    assert why == {
        "left_arm": "80% outside the observations, 17.1% of the points unexplained by "
        "torso, left_leg"
    }
    # a limb lost by another measure, or standing outside itself, keeps its name
    E2 = _evidence(left_arm=arm, left_leg={"unexplained": 0.15, "outside": 0.95})
    assert lost_limbs(E2, rule) == ("left_leg",)
    E3 = _evidence(left_arm=arm, left_leg={"unexplained": 0.15, "outside": DISPLACED + 0.05})
    assert lost_limbs(E3, rule) == ("left_leg",)
    # the arm past the threshold itself: the leg's points are its own too
    E4 = _evidence(left_arm={**arm, "unexplained": 0.03}, left_leg={"unexplained": 0.15})
    assert lost_limbs(E4, rule) == ("left_arm",)
    # no limb outside: the limbs with the points
    assert lost_limbs(_evidence(left_leg={"unexplained": 0.15}), rule) == ("left_leg",)
    # frames stacked: each named as on its own
    E5 = _evidence(left_leg={"unexplained": 0.15})
    stack = np.stack([E, E2, E3, E4, E5])
    assert np.array_equal(rule.named(stack), np.stack([rule.named(e) for e in stack]))
    assert rule.named(stack[None]).shape == (1, 5, len(LIMB_PARTS))


def test_a_rule_held_over_two_frames_needs_the_measure_past_its_threshold_on_both():
    """A limb is lost when a measure passes its threshold on the frame and the one before
    (the least of the two): a one-frame spike is not, the same limb on two frames is, and
    the reasons give the lesser value."""
    rule = LostRule((0.4, np.inf, 0.02, np.inf, np.inf, np.inf), frames=2)
    spike = _evidence(left_leg={"unexplained": 0.03})
    quiet = _evidence(left_leg={"unexplained": 0.01})
    other = _evidence(right_leg={"unexplained": 0.05})
    assert lost_limbs(spike, rule) == ("left_leg",)  # no frame before: the frame alone
    assert lost_limbs(spike, rule, before=[quiet]) == ()
    assert lost_limbs(spike, rule, before=[other]) == ()  # another limb the frame before
    later = _evidence(left_leg={"unexplained": 0.05})
    assert lost_limbs(later, rule, before=[quiet, spike]) == ("left_leg",)
    assert lost_reasons(later, rule, before=[spike]) == {
        "left_leg": "3.0% of the points unexplained"
    }
    seq = np.stack([quiet, spike, quiet, spike, later, later, quiet])
    assert rule.flags(seq).tolist() == [False, False, False, False, True, True, False]
    assert LostRule(rule.thresholds).flags(seq).tolist() == [False, True, False, True] + [
        True,
        True,
        False,
    ]
    assert rule.describe() == "outside > 0.4, unexplained > 0.02 on 2 frames in a row"
    with pytest.raises(InputError, match="frames must be an integer ≥ 1, found 0"):
        LostRule(rule.thresholds, frames=0)


def test_the_rule_round_trips_and_the_shipped_one_loads(tmp_path):
    rule = LostRule((0.3, np.inf, 0.05, 0.5, 0.04, 0.12), frames=3)
    rule.write(tmp_path / "r.json", note="test")
    assert LostRule.read(tmp_path / "r.json") == rule
    (tmp_path / "old.json").write_text('{"thresholds": {"outside": 0.3}}')  # before frames
    assert LostRule.read(tmp_path / "old.json").frames == 1
    assert LostRule.read(tmp_path / "old.json").disagree == (np.inf,) * len(DISAGREEMENT)
    far = LostRule(rule.thresholds, 2, disagree=(0.2, np.inf))
    far.write(tmp_path / "far.json")
    assert LostRule.read(tmp_path / "far.json") == far
    assert far.describe().endswith("on 2 frames in a row; disagreement: forward > 0.2 m")
    assert far.disagrees(np.array([[0.1, 5.0], [0.25, 0.0]])).tolist() == [False, True]
    with pytest.raises(InputError, match="expected 2 disagreement thresholds"):
        LostRule(rule.thresholds, disagree=(0.2,))
    (tmp_path / "zero.json").write_text('{"thresholds": {}, "frames": 0}')
    with pytest.raises(FormatError, match=r"zero\.json is not a rule file"):
        LostRule.read(tmp_path / "zero.json")
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
    tracks = dict(evidence=[E[:1000], E[1000:]], bad=[bad[:1000], bad[1000:]], good_rate=0.02)
    rule = fit_rule(**tracks, measures=EVIDENCE)
    f = rule.flags(E)
    assert np.count_nonzero(f & ~bad) <= 0.02 * np.count_nonzero(~bad)
    assert np.count_nonzero(f & bad) >= 0.95 * np.count_nonzero(bad)
    assert np.isfinite(rule.thresholds[k])
    assert "speed" not in FITTED and fit_rule(**tracks).thresholds[k] == np.inf  # default
    # a limb mostly outside the observations is lost whatever the fit sees (START)
    assert rule.thresholds[EVIDENCE.index("outside")] == START["outside"] == 0.9
    only = fit_rule(**tracks, measures=("speed",), start={})
    assert only.thresholds[EVIDENCE.index("outside")] == np.inf and only.thresholds[k] < 0.3
    assert "left_arm" in lost_limbs(_evidence(left_arm={"outside": 0.95}))  # shipped
    with pytest.raises(InputError, match=r"must be among .*found pace"):
        fit_rule(**tracks, measures=("speed", "pace"))


def test_fit_rule_counts_the_fixed_disagreement_against_the_budget():
    """Bad frames whose evidence is clean but where another track places a limb 300 mm off
    (a limb wrong inside the hull) are flagged by the disagreement at its fixed thresholds,
    not fitted; the good frames it flags leave less of the budget to the evidence."""
    rng = np.random.default_rng(2)
    n = 2000
    E = np.abs(rng.normal(0.0, 0.01, (n, len(LIMB_PARTS), len(EVIDENCE))))
    bad = rng.random(n) < 0.05
    D = np.zeros((n, len(DISAGREEMENT)))
    D[:, 1] = rng.uniform(0.0, 0.12, n)  # good frames: the tracks within 120 mm
    D[bad, 1] = rng.uniform(0.25, 0.4, bad.sum())
    rule = fit_rule([E], [bad], good_rate=0.02, disagreement=[D])
    assert rule.disagree == DISAGREE == (0.15, 0.15)
    assert rule.disagrees(D).tolist() == bad.tolist()
    assert rule.thresholds == (0.9,) + (np.inf,) * (len(EVIDENCE) - 1)  # none left for them
    # 1.5 % of the good frames disagree too: only 0.5 % left for the evidence
    k = EVIDENCE.index("unexplained")
    E[bad, 0, k] += rng.uniform(0.0, 0.05, bad.sum())  # the more budget, the more flagged
    D[rng.choice(np.flatnonzero(~bad), int(0.015 * np.count_nonzero(~bad)), replace=False), 0] = 1
    kept = fit_rule([E], [bad], good_rate=0.02, disagreement=[D], disagree=(0.5, np.inf))
    f = kept.flags(E) | kept.disagrees(D)
    assert kept.disagree == (0.5, np.inf) and np.isfinite(kept.thresholds[k])
    assert np.count_nonzero(f & ~bad) <= 0.02 * np.count_nonzero(~bad)
    alone = fit_rule([E], [bad], good_rate=0.02)
    assert kept.thresholds[k] > alone.thresholds[k]


def test_fit_rule_holds_the_budget_in_each_group():
    """Good frames of one category (group) pass a threshold the pooled budget affords but
    that category's does not: with the groups given, the fit does not take it."""
    rng = np.random.default_rng(3)
    n = 1000
    k = EVIDENCE.index("outside")
    E = [np.abs(rng.normal(0.0, 0.01, (n, len(LIMB_PARTS), len(EVIDENCE)))) for _ in range(3)]
    bad = [rng.random(n) < 0.05 for _ in range(3)]
    for e, b in zip(E, bad, strict=True):
        e[b, 1, k] += rng.uniform(0.3, 0.9, b.sum())  # the lower, the more flagged
    # category "c": 8 % of its good frames have a limb 60 % outside (2.7 % of all)
    E[2][rng.choice(np.flatnonzero(~bad[2]), int(0.08 * np.count_nonzero(~bad[2]))), 1, k] = 0.6
    pooled = fit_rule(E, bad, good_rate=0.04)
    grouped = fit_rule(E, bad, good_rate=0.04, groups=["a", "b", "c"])
    assert pooled.thresholds[k] < 0.6 <= grouped.thresholds[k]
    c = grouped.flags(E[2]) & ~bad[2]
    assert np.count_nonzero(c) <= 0.04 * np.count_nonzero(~bad[2])


def test_fit_rule_held_over_frames_leaves_one_frame_spikes_of_good_frames_alone():
    """Bad frames come in runs, good frames have one-frame spikes of the same size: fitted
    on the evidence held over two frames, the rule flags the runs and not the spikes."""
    rng = np.random.default_rng(1)
    n = 3000
    E = np.abs(rng.normal(0.0, 0.01, (n, len(LIMB_PARTS), len(EVIDENCE))))
    k = EVIDENCE.index("unexplained")
    bad = np.zeros(n, dtype=bool)
    for s in range(100, n, 300):
        bad[s : s + 20] = True
    E[bad, 3, k] += 0.05
    spikes = rng.choice(np.flatnonzero(~bad[1:] & ~bad[:-1]) + 1, 150, replace=False)
    E[spikes, 4, k] += 0.05  # 5 % of the good frames, each alone
    one = fit_rule([E], [bad], good_rate=0.02)
    two = fit_rule([E], [bad], good_rate=0.02, frames=2)
    assert two.frames == 2 and np.isfinite(two.thresholds[k])
    f1, f2 = one.flags(E), two.flags(E)
    assert np.count_nonzero(f2 & ~bad) <= 0.02 * np.count_nonzero(~bad)
    assert np.count_nonzero(f2 & bad) >= 0.9 * np.count_nonzero(bad)  # a run's first frame
    assert np.count_nonzero(f2 & ~bad) < np.count_nonzero(f1 & ~bad)
