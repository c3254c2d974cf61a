"""Frame evidence → lost limbs: the one rule that flags a limb ``lost``, for every tracker.

Each tracked frame's evidence (:meth:`~meshmocap.estimate.recovery.reinit.Recovery.assess`
computes it after every frame, the global pass after every frame it rewrites) is, per limb
(:data:`~meshmocap.estimate.recovery.quality.LIMB_PARTS`), the measures named in
:data:`EVIDENCE`:

* ``outside``, ``buried``, ``unexplained`` — the fit quality against the observations
  (:func:`~meshmocap.estimate.recovery.quality.fit_quality`: fractions of the limb's
  vertices outside or deep inside the observed solid, fraction of the observed points no
  vertex explains that lie nearest to the limb);
* ``unseen`` — 1 while the observations miss the limb where it was last seen and the
  tracked limb has jumped away (:class:`~meshmocap.estimate.recovery.reinit.Recovery`), else 0;
* ``residual`` — metres (RMS over the limb's vertices) between the tracked mesh and the
  articulated pose fitted to it: a limb the tracker bent out of any pose of the skeleton;
* ``speed`` — metres per frame the limb's joints moved relative to the pelvis since the
  frame before (the largest over its joints): a limb that jumped.

The rule (:class:`LostRule`) is a threshold per measure and a number of frames: a limb is
lost when one of its measures exceeds its threshold on that many frames in a row, the frame
and those just before it (:attr:`LostRule.frames`; the evidence the rule reads is, per limb
and measure, the least over those frames, :meth:`LostRule.persisted`). A fit that is off for
a single frame (a fast limb the tracker catches up with, a hull's phantom) is not a limb
lost; a lost limb stays lost for many frames. The rule ships as data
(``data/lost_rule.json``, :data:`RULE_FILE`), fitted by ``benchmarks/bench_lost.py``
(:func:`fit_rule`) on tracks of the pose library's motions by every tracker, and scored
there leaving each motion category out of the fit in turn; the file's ``note`` says on
which tracks it was fitted. The fit gives thresholds only to the measures of
:data:`FITTED` and keeps its budget of good frames flagged in every motion category it
sees, so that the rule holds on one it has not seen; the disagreement's thresholds are
fixed (:data:`DISAGREE`).
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from dataclasses import dataclass, replace
from functools import cache
from importlib import resources
from pathlib import Path

import numpy as np

from meshmocap.errors import FormatError, InputError
from meshmocap.estimate.recovery.quality import LIMB_PARTS

__all__ = [
    "DISAGREE",
    "DISAGREEMENT",
    "DISPLACED",
    "EVIDENCE",
    "FITTED",
    "RULE_FILE",
    "START",
    "LostRule",
    "fit_rule",
    "lost_limbs",
    "lost_reasons",
    "shipped_rule",
]

#: The measures of a limb's evidence, in the order of the last axis of an evidence array.
EVIDENCE = ("outside", "buried", "unexplained", "unseen", "residual", "speed")
#: The tracks' disagreement on a frame the two-way pass chose (metres, the largest over its
#: limbs of the largest joint distance on the limb), in the order of the last axis of a
#: disagreement array: ``forward`` — to the forward track, where the rule does not flag that
#: track's frame; ``keyframe`` — to a keyframe's track, on the limbs the rule passes there.
DISAGREEMENT = ("forward", "keyframe")
#: Metres: the disagreement thresholds of a fitted rule, both measures (:func:`fit_rule`):
#: the bad-frame criterion itself. Another track the evidence does not rule out places a
#: joint of the limb this far from the chosen one: one of the two is wrong by about that
#: much, and the evidence cannot say which. Fixed, not fitted: fitted, the threshold
#: follows the few bad frames left after the pass in the categories it saw.
DISAGREE = (0.15, 0.15)
#: The measures of :data:`EVIDENCE` a fitted rule gives thresholds (:func:`fit_rule`): the
#: fit to the observations. The others (``buried``, ``unseen``, ``residual``, ``speed``)
#: depend on the motion (arms held against the trunk are buried in the hull) and, fitted,
#: flag good frames of a category the fit has not seen.
FITTED = ("outside", "unexplained")
#: The thresholds a fitted rule starts from, which the fit may only lower (:func:`fit_rule`):
#: a limb with more than 90 % of its vertices outside the observed solid is lost whatever
#: the tracks it is fitted on show (a visual hull contains the body; a limb the
#: observations miss, held where they do not show it, stands outside it).
START = {"outside": 0.9}
#: The fraction of a limb's vertices outside the observed solid beyond which the limb is
#: named for the points another limb leaves unexplained (:meth:`LostRule.named`): where a
#: limb past a threshold only by the points unexplained nearest to it stands inside the
#: observations itself while another limb stands this far outside them, the points are
#: that limb's, put elsewhere (an arm turned away from the trunk leaves its points nearest
#: the trunk or a leg; counted for the nearest tracked vertex, they named those). Above the
#: cage's good frames (its smooth arms often stand half outside a hull). The frame is lost
#: either way (:meth:`LostRule.flags`).
DISPLACED = 0.7
#: The shipped rule's file (in the package).
RULE_FILE = Path(str(resources.files("meshmocap.estimate.recovery") / "data" / "lost_rule.json"))


@dataclass(frozen=True)
class LostRule:
    """A threshold per measure of :data:`EVIDENCE` (``inf``: the measure never flags), held
    for a number of frames in a row, and one per measure of :data:`DISAGREEMENT`.

    Attributes
    ----------
    thresholds : tuple of float, one per :data:`EVIDENCE` measure (units as there)
    frames : int
        Frames in a row (the frame assessed and those just before it) a measure must exceed
        its threshold on for the limb to be lost (1: the frame alone).
    disagree : tuple of float, metres, one per :data:`DISAGREEMENT` measure: a frame the
        two-way pass chose is flagged where another track places a limb farther off
        (:meth:`disagrees`; ``inf``: never)
    """

    thresholds: tuple[float, ...]
    frames: int = 1
    disagree: tuple[float, ...] = (np.inf,) * len(DISAGREEMENT)

    def __post_init__(self) -> None:
        if len(self.thresholds) != len(EVIDENCE):
            raise InputError(
                f"lost rule: expected {len(EVIDENCE)} thresholds ({', '.join(EVIDENCE)}), "
                f"found {len(self.thresholds)}"
            )
        if isinstance(self.frames, bool) or not isinstance(self.frames, int) or self.frames < 1:
            raise InputError(f"lost rule: frames must be an integer ≥ 1, found {self.frames!r}")
        if len(self.disagree) != len(DISAGREEMENT):
            raise InputError(
                f"lost rule: expected {len(DISAGREEMENT)} disagreement thresholds "
                f"({', '.join(DISAGREEMENT)}), found {len(self.disagree)}"
            )

    def limb_lost(self, evidence: np.ndarray) -> np.ndarray:
        """(..., L) bool: each limb of ``evidence`` (..., L, E) past a threshold, the
        evidence taken as it is (held over frames already: :meth:`persisted`)."""
        return np.any(np.asarray(evidence) > np.asarray(self.thresholds), axis=-1)

    def named(self, evidence: np.ndarray) -> np.ndarray:
        """(..., L) bool: the limbs named lost on frames of ``evidence`` (..., L, E) (held
        over frames already: :meth:`persisted`): those past a threshold
        (:meth:`limb_lost`), except that on a frame where a limb stands more than
        :data:`DISPLACED` outside the observations, the limbs past the ``unexplained``
        threshold alone that stand inside them are replaced by the limbs outside (the
        points unexplained are theirs)."""
        e = np.asarray(evidence, dtype=np.float64)
        past = e > np.asarray(self.thresholds)
        lost = past.any(axis=-1)
        out, unx = EVIDENCE.index("outside"), EVIDENCE.index("unexplained")
        alone = past[..., unx] & ~np.delete(past, unx, axis=-1).any(axis=-1)
        displaced = e[..., out] > DISPLACED
        blamed = lost & alone & ~displaced
        moved = blamed.any(axis=-1, keepdims=True) & displaced.any(axis=-1, keepdims=True)
        return np.where(moved, (lost & ~blamed) | displaced, lost)

    def persisted(self, evidence: np.ndarray, before: Sequence[np.ndarray] = ()) -> np.ndarray:
        """(L, E) float64: the evidence the rule reads on a frame, per limb and measure the
        least of the frame's ``evidence`` (L, E) and that of the frames just before it
        (``before``, oldest first; the last :attr:`frames` − 1 are used, fewer where fewer
        were assessed)."""
        out = np.asarray(evidence, dtype=np.float64)
        for e in list(before)[-(self.frames - 1) :] if self.frames > 1 else ():
            out = np.minimum(out, np.asarray(e, dtype=np.float64))
        return out

    def sequence(self, evidence: np.ndarray) -> np.ndarray:
        """(T, L, E) float64: :meth:`persisted` at each frame of ``evidence`` (T, L, E),
        consecutive frames in order (the first frames with fewer before them)."""
        e = np.asarray(evidence, dtype=np.float64)
        out = e.copy()
        for s in range(1, min(self.frames, len(e))):
            out[s:] = np.minimum(out[s:], e[:-s])
        return out

    def flags(self, evidence: np.ndarray) -> np.ndarray:
        """(T,) bool: the frames of ``evidence`` (T, L, E), consecutive frames in order,
        with a limb lost (:meth:`sequence`)."""
        return self.limb_lost(self.sequence(evidence)).any(axis=-1)

    def disagrees(self, disagreement: np.ndarray) -> np.ndarray:
        """(...) bool: where ``disagreement`` (..., D) metres (:data:`DISAGREEMENT`) passes a
        threshold of :attr:`LostRule.disagree`."""
        return np.any(np.asarray(disagreement) > np.asarray(self.disagree), axis=-1)

    def describe(self) -> str:
        """The thresholds used, one ``name > value`` each, the frames in a row, and the
        disagreement's (metres)."""
        text = ", ".join(
            f"{n} > {t:.3g}"
            for n, t in zip(EVIDENCE, self.thresholds, strict=True)
            if np.isfinite(t)
        )
        text += f" on {self.frames} frames in a row" if self.frames > 1 else ""
        far = [
            f"{n} > {t:.3g} m"
            for n, t in zip(DISAGREEMENT, self.disagree, strict=True)
            if np.isfinite(t)
        ]
        return text + (f"; disagreement: {', '.join(far)}" if far else "")

    def write(self, path: str | Path, *, note: str = "") -> None:
        """Save the rule as JSON (``inf`` as null)."""
        th = {
            n: (float(t) if np.isfinite(t) else None)
            for n, t in zip(EVIDENCE, self.thresholds, strict=True)
        }
        far = {
            n: (float(t) if np.isfinite(t) else None)
            for n, t in zip(DISAGREEMENT, self.disagree, strict=True)
        }
        rule = {"thresholds": th, "frames": self.frames, "disagreement": far, "note": note}
        Path(path).write_text(json.dumps(rule, indent=1) + "\n")

    @classmethod
    def read(cls, path: str | Path) -> LostRule:
        """A rule saved by :meth:`write` (one without ``frames``: the frame alone; without
        ``disagreement``: none flags)."""
        try:
            rule = json.loads(Path(path).read_text())
            th, far = rule["thresholds"], rule.get("disagreement") or {}
            return cls(
                tuple(np.inf if th.get(n) is None else float(th[n]) for n in EVIDENCE),
                int(rule.get("frames", 1)),
                tuple(np.inf if far.get(n) is None else float(far[n]) for n in DISAGREEMENT),
            )
        except (KeyError, TypeError, ValueError, AttributeError, InputError) as e:
            raise FormatError(f"lost rule: {path} is not a rule file ({e})") from None


@cache
def shipped_rule() -> LostRule:
    """The rule shipped with the package (:data:`RULE_FILE`)."""
    return LostRule.read(RULE_FILE)


def lost_limbs(
    evidence: np.ndarray, rule: LostRule | None = None, *, before: Sequence[np.ndarray] = ()
) -> tuple[str, ...]:
    """The limbs lost on a frame, in :data:`~meshmocap.estimate.recovery.quality.LIMB_PARTS`
    order: those with a measure of ``evidence`` (L, E) (:data:`EVIDENCE`) over ``rule``'s
    threshold (default :func:`shipped_rule`), on this frame and, for a rule held over
    frames, on the frames just before it (``before``: their evidence, oldest first;
    :meth:`LostRule.persisted`), or the limbs standing outside the observations that the
    unexplained points belong to (:meth:`LostRule.named`)."""
    rule = rule or shipped_rule()
    lost = rule.named(rule.persisted(evidence, before))
    return tuple(n for n, k in zip(LIMB_PARTS, lost, strict=True) if k)


def lost_reasons(
    evidence: np.ndarray, rule: LostRule | None = None, *, before: Sequence[np.ndarray] = ()
) -> dict[str, str]:
    """Per lost limb (:func:`lost_limbs`), why, in words: each measure over its threshold
    (the least value over the frames the rule holds it for)."""
    rule = rule or shipped_rule()
    evidence = rule.persisted(evidence, before)
    words = {
        "outside": lambda v: f"{100 * v:.0f}% outside the observations",
        "buried": lambda v: f"{100 * v:.0f}% buried in the body",
        "unexplained": lambda v: f"{100 * v:.1f}% of the points unexplained",
        "unseen": lambda v: "not observed where it was last seen",
        "residual": lambda v: f"{1000 * v:.0f} mm off any pose of the skeleton",
        "speed": lambda v: f"moved {1000 * v:.0f} mm since the last frame",
    }
    evidence = np.asarray(evidence)
    named, past = rule.named(evidence), rule.limb_lost(evidence)
    blamed = past & ~named
    unx = evidence[blamed, EVIDENCE.index("unexplained")].sum()
    others = ", ".join(n for n, k in zip(LIMB_PARTS, blamed, strict=True) if k)
    out = {}
    for n, row, k in zip(LIMB_PARTS, evidence, named, strict=True):
        why = [words[m](v) for m, v, t in zip(EVIDENCE, row, rule.thresholds, strict=True) if v > t]
        if k and not why:  # named for the points another limb leaves unexplained
            why = [
                words["outside"](row[EVIDENCE.index("outside")]),
                f"{100 * unx:.1f}% of the points unexplained by {others}",
            ]
        if k:
            out[n] = ", ".join(why)
    return out


def fit_rule(
    evidence: list[np.ndarray],
    bad: list[np.ndarray],
    *,
    good_rate: float = 0.04,
    quantiles: np.ndarray | None = None,
    frames: int = 1,
    measures: Sequence[str] = FITTED,
    groups: Sequence[str] | None = None,
    disagreement: list[np.ndarray] | None = None,
    disagree: Sequence[float] = DISAGREE,
    start: dict[str, float] = START,
) -> LostRule:
    """Thresholds that flag as many bad frames as possible while flagging at most
    ``good_rate`` of the good frames: greedily, the measure of ``measures`` and threshold
    (a quantile of that measure's frame maximum over the good frames) that flags the most
    bad frames not yet flagged per good frame newly flagged, within the budget, until none
    adds any. The disagreement's thresholds are not fitted: ``disagree`` (the frames they
    flag count against the budget).

    Parameters
    ----------
    evidence : list of (T, L, E) float64, one per track, its frames in order
    bad : list of (T,) bool, the frames with a joint off (the label)
    good_rate : float, the share of good frames the rule may flag
    quantiles : (q,) float, candidate quantiles of the good frames' values
    frames : int, the rule's frames in a row (:attr:`LostRule.frames`): the thresholds
        are fitted to the evidence held over that many frames (:meth:`LostRule.sequence`)
    measures : sequence of str, the measures of :data:`EVIDENCE` given a threshold (the
        others stay ``inf``; default :data:`FITTED`)
    groups : sequence of str, optional, one per track (its motion category): the budget
        then holds in every group, the share of each group's good frames flagged at most
        ``good_rate`` (a margin for a group the fit has not seen: a threshold that only
        the pooled frames afford, spent on one group, is not taken)
    disagreement : list of (T, D) float64, metres, optional
        Each track's disagreement per frame (:data:`DISAGREEMENT`; zeros on a forward
        track, the default)
    disagree : sequence of float, metres, the rule's disagreement thresholds, one per
        :data:`DISAGREEMENT` measure (default :data:`DISAGREE`)
    start : dict of measure → float, the thresholds the fit starts from and may only lower
        (default :data:`START`; the other measures start at ``inf``)

    Returns
    -------
    LostRule
    """
    unknown = sorted((set(measures) | set(start)) - set(EVIDENCE))
    if unknown:
        raise InputError(
            f"fit_rule: measures (and start) must be among {', '.join(EVIDENCE)}, "
            f"found {', '.join(unknown)}"
        )
    if groups is not None and len(groups) != len(evidence):
        raise InputError(
            f"fit_rule: expected one group per track ({len(evidence)}), found {len(groups)}"
        )
    hold = LostRule((np.inf,) * len(EVIDENCE), frames, tuple(float(t) for t in disagree))
    D = len(DISAGREEMENT)
    if disagreement is None:
        disagreement = [np.zeros((len(e), D)) for e in evidence]
    # (N, E): worst limb per frame, of the evidence the rule reads
    X = np.concatenate([hold.sequence(e).max(axis=1) for e in evidence])
    far = np.concatenate(
        [hold.disagrees(np.asarray(d, np.float64).reshape(-1, D)) for d in disagreement]
    )
    y = np.concatenate(bad).astype(bool)
    groups = [""] * len(evidence) if groups is None else list(groups)
    names = sorted(set(groups))
    g = np.repeat([names.index(k) for k in groups], [len(e) for e in evidence])
    n_good = np.maximum(np.bincount(g[~y], minlength=len(names)), 1)
    q = np.linspace(0.9, 1.0, 101) if quantiles is None else np.asarray(quantiles)
    good = X[~y]
    candidates = [
        np.unique(np.quantile(good[:, k], q)) if len(good) and m in measures else np.empty(0)
        for k, m in enumerate(EVIDENCE)
    ]
    th = np.array([start.get(m, np.inf) for m in EVIDENCE], dtype=np.float64)
    while True:
        flagged = far | (th < X).any(axis=1)
        bad0, good0 = np.count_nonzero(flagged & y), np.count_nonzero(flagged & ~y)
        best, gain = None, 0.0
        for k in range(X.shape[1]):
            for t in candidates[k]:
                if t >= th[k]:
                    continue
                f = flagged | (X[:, k] > t)
                spent = np.bincount(g[f & ~y], minlength=len(names)) / n_good
                if spent.max() > good_rate:
                    continue
                new_bad = np.count_nonzero(f & y) - bad0
                score = new_bad / (np.count_nonzero(f & ~y) - good0 + 1.0)
                if new_bad > 0 and score > gain:
                    best, gain = (k, t), score
        if best is None:
            return replace(hold, thresholds=tuple(float(v) for v in th))
        th[best[0]] = best[1]
