"""Gait analysis from joint trajectories (cage-manifold-tracking.txt §6.3, Fig. 11): gait
events and cycles, spatio-temporal parameters, hip and knee flexion curves, ankle heights
and wrist paths.

Protocol
--------
Only the 15 evaluation joints are used (no toe or heel marker), so every event is an event
of the **ankle joint**:

* A foot is **planted** while its ankle moves horizontally slower than the body walks (the
  walking speed: the median horizontal speed of the pelvis; at least 0.25 m/s) *and* lies
  low: above the ankle's stance height by less than ``lift`` (70 %) of its swing clearance
  (a tracked ankle rising early at push-off must not cut the stance short: at 50 %, a
  slow walk's foot off came 1.9 frames early on a cage track; a foot in the air, as in
  a jump, still ends it). A planted foot is still and a swinging one overtakes the body, so
  the ankle crosses that speed where it decelerates and accelerates fastest: the steepest,
  least noise-sensitive place to time an event (half the walking speed, in the slow tail of
  the landing, put tracked events up to 2.6 frames off the truth's on CMU 05_01; the
  walking speed, 2.1; stance then takes 57–61 % of a CMU walk's cycle, as a toe-off would,
  but 47–49 % of a run's, longer than a toe-off's).
  ``strike_factor`` and ``off_factor`` scale the two crossings separately. Positions are
  smoothed first by a Savitzky–Golay filter (quadratic, ``smooth`` = 0.1 s), which also
  gives the velocities.
* Interruptions of a stance shorter than ``min_swing`` (0.1 s) are closed and stances
  shorter than ``min_stance`` (0.08 s) are dropped: a few centimetres of jitter of a tracked
  ankle at stance neither end a stance nor start a spurious one.
* **Foot strike** is the start of a stance, **foot off** its end, timed to a fraction of a
  frame where the ankle's speed crosses the walking speed (linear interpolation). Events within
  two frames of the clip's ends, or whose smoothing window reaches a frame flagged as
  unusable, are dropped.
* A **cycle** runs from a foot strike to the next strike of the same foot with one foot off
  in between; a **step** from a strike of one foot to the next strike of the other.
* Stride length: horizontal distance between consecutive stance positions of one foot (the
  median ankle position over each stance); step length: distance from the other foot's last
  stance position to the landing foot's, along the direction of travel; speed = stride
  length / stride time; cadence = 60 / mean step time (steps per minute); stance % = time
  from strike to foot off over the stride time.

The **sagittal plane** of a frame is spanned by world up (Z) and the subject's forward
direction: horizontal, perpendicular to the line from the right to the left hip, smoothed
over one second. Angles are measured in it (degrees), from vectors projected on it:

* **hip flexion**: the angle from the trunk's downward axis (thorax → pelvis) to the thigh
  (hip → knee), positive when the knee is in front of the trunk line (flexion), negative
  behind it (extension);
* **knee flexion**: the angle from the thigh's direction (hip → knee) to the shank's (knee →
  ankle), positive when the shank is rotated backwards (flexion), 0 for a straight leg,
  negative when hyperextended.

Curves per cycle are resampled to 0, 1, …, 100 % of the cycle (101 samples, linear
interpolation). Walking in place (a treadmill) is out of scope: the feet must travel.

References
----------
- E. Duveau, S. Courtemanche, L. Reveret, E. Boyer, *Cage-based motion recovery
  using manifold learning*, International Conference on 3D Imaging, Modeling,
  Processing, Visualization and Transmission (3DIMPVT), 2012.
- A. Savitzky, M. J. E. Golay, *Smoothing and differentiation of data by
  simplified least squares procedures*, Analytical Chemistry 36(8):1627–1639, 1964.
  https://doi.org/10.1021/ac60214a047
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass, field

import numpy as np

from meshmocap._tolerances import SAME_FPS, ZERO_EXTENT
from meshmocap.analysis.gait_signals import (
    SIDES,
    close_gaps,
    drop_short,
    event_usable,
    fill_invalid,
    flexion_angles,
    forward,
    smoothed,
    stance_events,
    stance_mask,
)
from meshmocap.errors import InputError
from meshmocap.io.capture import Capture
from meshmocap.io.results import Track

_JOINTS = (
    "pelvis",
    "thorax",
    *(f"{s}_{j}" for s in SIDES for j in ("hip", "knee", "ankle", "wrist")),
)
#: Samples of a normalised cycle curve: 0, 1, ..., 100 % of the cycle.
CYCLE_SAMPLES = 101
#: Ankle speeds that time a foot strike and a foot off, as fractions of the walking speed.
STRIKE_FACTOR, OFF_FACTOR = 1.0, 1.0
#: Fraction of an ankle's height range above which its foot is in the air.
LIFT = 0.7
#: Frame flags (:data:`meshmocap.io.results.FRAME_FLAGS`) whose joints gait analysis ignores.
UNUSABLE_FLAGS = ("failed", "missing", "lost")


@dataclass(frozen=True, eq=False)
class GaitCycle:
    """One gait cycle of one foot, from its strike to its next strike.

    Attributes
    ----------
    side : ``"left"`` or ``"right"``
    strike, foot_off, end : float, frame positions (fractional) of the foot strike, the foot
        off and the next strike of the same foot
    stride_time : float, seconds; stride_length : float, metres
    stance_pct : float, percent of the cycle from strike to foot off
    step_time, step_length : float, the step that ends this cycle (the other foot's last
        strike → this foot's next strike), seconds and metres; NaN when the other foot's
        strike was not found
    hip, knee : (101,) float64, flexion in degrees at 0, 1, …, 100 % of the cycle
    """

    side: str
    strike: float
    foot_off: float
    end: float
    stride_time: float
    stride_length: float
    stance_pct: float
    step_time: float
    step_length: float
    hip: np.ndarray
    knee: np.ndarray

    @property
    def speed(self) -> float:
        """Stride length over stride time, m/s."""
        return self.stride_length / self.stride_time

    @property
    def swing_pct(self) -> float:
        """Percent of the cycle from foot off to the next strike."""
        return 100.0 - self.stance_pct


#: Fields of :class:`GaitSummary` with their units, in CSV order.
SUMMARY_FIELDS = (
    "cadence_steps_per_min",
    "stride_time_s",
    "stride_length_m",
    "speed_m_per_s",
    "step_time_s",
    "step_length_m",
    "stance_pct",
    "swing_pct",
)


@dataclass(frozen=True)
class GaitSummary:
    """Means over the cycles (and steps) of one side, or of both (``side="both"``); NaN
    where there is nothing to average. Units are in the field names."""

    side: str
    n_cycles: int
    n_steps: int
    cadence_steps_per_min: float
    stride_time_s: float
    stride_length_m: float
    speed_m_per_s: float
    step_time_s: float
    step_length_m: float
    stance_pct: float
    swing_pct: float

    def as_dict(self) -> dict[str, float]:
        """The :data:`SUMMARY_FIELDS` as a dict."""
        return {k: getattr(self, k) for k in SUMMARY_FIELDS}


@dataclass(frozen=True, eq=False)
class Gait:
    """Gait of a clip: curves per frame, events, cycles and steps.

    Attributes
    ----------
    fps : float, frames per second
    frames : (T,) int64, frame numbers (the input's; positions 0…T−1 index every array)
    valid : (T,) bool, frames whose joints were usable (not flagged, not absent)
    times : (T,) float64, seconds from the first frame
    ankle_height : (T, 2) float64, left/right ankle height above the floor (z = 0), metres
    ankle_speed : (T, 2) float64, left/right ankle horizontal speed (smoothed), m/s
    wrist_sagittal : (T, 2, 2) float64, left/right wrist (forward, up) relative to the
        pelvis in the sagittal plane, metres
    hip_flexion, knee_flexion : (T, 2) float64, left/right, degrees (module docstring)
    strikes, foot_offs : tuple of two (k,) float64 arrays, left/right event positions
        (fractional frame positions)
    cycles : tuple of :class:`GaitCycle`, ordered by strike
    steps : (s, 4) float64, one row per step: landing side (0 left, 1 right), step time
        (s), step length (m), landing position (fractional frame)
    strike_speed, off_speed : float, m/s, the ankle speeds that timed the strikes and offs
    progression_speed : float, m/s, median horizontal speed of the pelvis
    message : str, why no gait was found (empty when one was)
    """

    fps: float
    frames: np.ndarray
    valid: np.ndarray
    times: np.ndarray
    ankle_height: np.ndarray
    ankle_speed: np.ndarray
    wrist_sagittal: np.ndarray
    hip_flexion: np.ndarray
    knee_flexion: np.ndarray
    strikes: tuple[np.ndarray, np.ndarray]
    foot_offs: tuple[np.ndarray, np.ndarray]
    cycles: tuple[GaitCycle, ...]
    steps: np.ndarray
    strike_speed: float
    off_speed: float
    progression_speed: float
    message: str = ""
    _cache: dict = field(default_factory=dict, repr=False)

    @property
    def found(self) -> bool:
        """Whether at least one step was found (cadence is then measured)."""
        return not self.message

    @property
    def cadence(self) -> float:
        """Steps per minute (NaN without a step)."""
        return self.summary().cadence_steps_per_min

    def frame_numbers(self, pos: np.ndarray | float) -> np.ndarray:
        """Fractional frame numbers of fractional positions ``pos`` (event positions)."""
        return np.interp(pos, np.arange(len(self.frames)), self.frames.astype(float))

    def side_cycles(self, side: str) -> tuple[GaitCycle, ...]:
        """The cycles of ``side`` (``"left"`` or ``"right"``)."""
        _check_side(side, both=False)
        return tuple(c for c in self.cycles if c.side == side)

    def summary(self, side: str = "both") -> GaitSummary:
        """Means of the cycles and steps of ``side`` (``"left"``, ``"right"`` or ``"both"``)."""
        _check_side(side, both=True)
        if side not in self._cache:
            self._cache[side] = _summary(self, side)
        return self._cache[side]


def _check_side(side: str, *, both: bool) -> None:
    choices = [*SIDES, "both"] if both else list(SIDES)
    if side not in choices:
        raise InputError(f"gait: side must be one of {choices}, found {side!r}")


def _summary(g: Gait, side: str) -> GaitSummary:
    cyc = g.cycles if side == "both" else g.side_cycles(side)
    st = g.steps if side == "both" else g.steps[g.steps[:, 0] == SIDES.index(side)]

    def mean(x) -> float:
        x = np.asarray(list(x), dtype=float)
        x = x[np.isfinite(x)]
        return float(x.mean()) if len(x) else float("nan")

    step_time = mean(st[:, 1])
    stride_time = mean(c.stride_time for c in cyc)
    # cadence from steps; from strides (two steps each) where no step was found
    cadence = 60.0 / step_time if np.isfinite(step_time) else 120.0 / stride_time
    stance = mean(c.stance_pct for c in cyc)
    return GaitSummary(
        side,
        len(cyc),
        len(st),
        cadence,
        stride_time,
        mean(c.stride_length for c in cyc),
        mean(c.speed for c in cyc),
        step_time,
        mean(st[:, 2]),
        stance,
        100.0 - stance,
    )


def gait_analysis(
    joints: np.ndarray,
    fps: float,
    names: tuple[str, ...] | list[str],
    *,
    valid: np.ndarray | None = None,
    frames: np.ndarray | None = None,
    strike_factor: float = STRIKE_FACTOR,
    off_factor: float = OFF_FACTOR,
    min_speed: float = 0.25,
    lift: float = LIFT,
    smooth: float = 0.1,
    min_swing: float = 0.1,
    min_stance: float = 0.08,
    max_step: float = 1.5,
) -> Gait:
    """Gait events, cycles, spatio-temporal parameters and flexion curves of a clip (see the
    module docstring for the protocol).

    Parameters
    ----------
    joints : (T, K, 3) float64
        Joint positions, metres, world frame (Z up), one row per frame at ``fps``.
    fps : float
        Frames per second.
    names : sequence of K str
        Joint names; needs pelvis, thorax and the left/right hip, knee, ankle and wrist.
    valid : (T,) bool, optional
        Frames whose joints can be used (default: all). Invalid frames may hold anything
        (NaN included); events near them are dropped and no cycle spans them.
    frames : (T,) int, optional
        Frame numbers to report (default 0…T−1).
    strike_factor, off_factor : float
        The ankle speeds that time a foot strike and a foot off, as fractions of the walking
        speed (the median horizontal speed of the pelvis), at least ``min_speed`` m/s.
    lift : float
        Fraction of the ankle's height range (stance height to its 95th percentile) above
        which a foot is in the air whatever its speed.
    smooth : float
        Savitzky–Golay window, seconds (0: no smoothing).
    min_swing, min_stance : float
        Seconds: shorter interruptions of a stance are closed, shorter stances dropped.
    max_step : float
        Seconds: a longer interval between strikes of the two feet is a pause, not a step.

    Returns
    -------
    Gait
        With ``message`` saying why when no step was found (then no cycle either).
    """
    J = np.asarray(joints, dtype=float)
    if J.ndim != 3 or J.shape[2] != 3 or len(J) < 3:
        raise InputError(f"gait: joints must have shape (T ≥ 3, K, 3), found {J.shape}")
    if len(names) != J.shape[1]:
        raise InputError(f"gait: expected {J.shape[1]} joint names, found {len(names)}")
    missing = [n for n in _JOINTS if n not in names]
    if missing:
        raise InputError(f"gait: joints {missing} are missing from {list(names)}")
    if not (np.isfinite(fps) and fps > 0):
        raise InputError(f"gait: fps must be a positive number, found {fps}")
    T = len(J)
    ok = np.ones(T, bool) if valid is None else np.asarray(valid, dtype=bool)
    if ok.shape != (T,):
        raise InputError(f"gait: valid must have shape ({T},), found {ok.shape}")
    if ok.sum() < 3:
        raise InputError(f"gait: fewer than 3 of the {T} frames are valid")
    if not np.all(np.isfinite(J[ok])):
        raise InputError("gait: joints contain NaN or infinite values in valid frames")
    fr = np.arange(T) if frames is None else np.asarray(frames, dtype=np.int64)
    if fr.shape != (T,):
        raise InputError(f"gait: frames must have shape ({T},), found {fr.shape}")
    idx = {n: list(names).index(n) for n in _JOINTS}
    J = fill_invalid(J, ok)
    w = 0 if smooth <= 0 else max(5, 2 * round(smooth * fps / 2) + 1)
    legs = [idx["left_ankle"], idx["right_ankle"], idx["pelvis"]]
    P = smoothed(J[:, legs], w)
    Vel = smoothed(J[:, legs], w, deriv=1) * fps
    speed = np.linalg.norm(Vel[:, :2, :2], axis=-1)  # (T, 2) ankles, horizontal
    v_prog = float(np.median(np.linalg.norm(Vel[ok, 2, :2], axis=-1)))
    v_on, v_off = max(min_speed, strike_factor * v_prog), max(min_speed, off_factor * v_prog)
    height = P[:, :2, 2]
    fwd = forward(J, idx, fps)
    rel = J[:, [idx["left_wrist"], idx["right_wrist"]]] - J[:, [idx["pelvis"]]]
    wrist = np.stack([np.einsum("tkj,tj->tk", rel, fwd), rel[..., 2]], axis=-1)
    hip, knee = flexion_angles(J, names, fwd)
    bad, margin = ~ok, max(2, w // 2 + 1)
    stances, strikes, offs = [], [], []
    for k in range(2):
        slow = speed[:, k] < min(v_on, v_off)
        base = np.median(height[ok & slow, k]) if (ok & slow).any() else height[ok, k].min()
        gate = base + lift * (np.percentile(height[ok, k], 95) - base)
        planted = stance_mask(speed[:, k], height[:, k] < gate, v_on, v_off)
        planted = drop_short(close_gaps(planted, round(min_swing * fps)), round(min_stance * fps))
        s, e, hs, to = stance_events(planted, speed[:, k], height[:, k], v_on, v_off, gate)
        # the smoothing window of an event must not reach into frames filled by interpolation
        hs, to = (
            np.array([p if event_usable(p, bad, bad_margin=margin) else np.nan for p in x])
            for x in (hs, to)
        )
        where = np.array([np.median(P[a:b, k, :2], axis=0) for a, b in zip(s, e, strict=True)])
        stances.append((s, e, where.reshape(-1, 2)))
        strikes.append(hs)
        offs.append(to)
    steps = _steps(strikes, stances, P[:, 2, :2], bad, fps, max_step)
    cycles = _cycles(strikes, offs, stances, steps, hip, knee, bad, fps, 2 * max_step)
    message = ""
    if v_prog < 0.15:
        message = (
            f"the pelvis travels {v_prog:.2f} m/s (median over the clip); gait analysis "
            "needs a walk or a run (at least 0.15 m/s)"
        )
    elif not len(steps):
        n = [int(np.isfinite(h).sum()) for h in strikes]
        message = (
            f"no step found in {T / fps:.1f} s: {n[0]} strikes of the left foot and "
            f"{n[1]} of the right (a step is a strike of one foot followed within "
            f"{max_step:g} s by one of the other)"
        )
    if message:
        cycles, steps = (), np.zeros((0, 4))
    return Gait(
        fps=float(fps),
        frames=fr,
        valid=ok,
        times=np.arange(T) / fps,
        ankle_height=height,
        ankle_speed=speed,
        wrist_sagittal=wrist,
        hip_flexion=hip,
        knee_flexion=knee,
        strikes=tuple(h[np.isfinite(h)] for h in strikes),  # type: ignore[arg-type]
        foot_offs=tuple(o[np.isfinite(o)] for o in offs),  # type: ignore[arg-type]
        cycles=cycles,
        steps=steps,
        strike_speed=v_on,
        off_speed=v_off,
        progression_speed=v_prog,
        message=message,
    )


def _steps(strikes, stances, pelvis, bad, fps, max_step) -> np.ndarray:
    """(s, 4) steps: landing side, time (s), length along the travel direction (m), landing
    position (frames)."""
    ev = sorted((p, k, r) for k in range(2) for r, p in enumerate(strikes[k]) if np.isfinite(p))
    t = np.arange(len(pelvis))
    rows = []
    for (p0, k0, r0), (p1, k1, r1) in itertools.pairwise(ev):
        if k0 == k1 or (p1 - p0) / fps > max_step or bad[int(p0) : int(np.ceil(p1)) + 1].any():
            continue
        d = np.array(
            [np.interp(p1, t, pelvis[:, c]) - np.interp(p0, t, pelvis[:, c]) for c in (0, 1)]
        )
        d /= max(np.linalg.norm(d), ZERO_EXTENT)
        length = float((stances[k1][2][r1] - stances[k0][2][r0]) @ d)
        rows.append((k1, (p1 - p0) / fps, length, p1))
    return np.array(rows, dtype=float).reshape(-1, 4)


def _cycles(
    strikes, offs, stances, steps, hip, knee, bad, fps, max_stride
) -> tuple[GaitCycle, ...]:
    """The cycles of both feet (consecutive stances of one foot, both strikes and the foot
    off between them found, no unusable frame inside)."""
    out = []
    pct = np.linspace(0.0, 1.0, CYCLE_SAMPLES)
    t = np.arange(len(bad))
    for k, side in enumerate(SIDES):
        hs, to, where = strikes[k], offs[k], stances[k][2]
        for r in range(len(hs) - 1):
            a, b, off = hs[r], hs[r + 1], to[r]
            if not (np.isfinite(a) and np.isfinite(b) and np.isfinite(off) and a < off < b):
                continue
            if (b - a) / fps > max_stride or bad[int(a) : int(np.ceil(b)) + 1].any():
                continue
            step = steps[steps[:, 3] == b]  # the step that ends this cycle, if found
            step_t, step_l = (step[0, 1], step[0, 2]) if len(step) else (np.nan, np.nan)
            s = a + pct * (b - a)
            curves = np.interp(s, t, hip[:, k]), np.interp(s, t, knee[:, k])
            out.append(
                GaitCycle(
                    side,
                    float(a),
                    float(off),
                    float(b),
                    (b - a) / fps,
                    float(np.linalg.norm(where[r + 1] - where[r])),
                    100.0 * (off - a) / (b - a),
                    float(step_t),
                    float(step_l),
                    *curves,
                )
            )
    return tuple(sorted(out, key=lambda c: c.strike))


def track_gait(track: Track, fps: float, **options) -> Gait:
    """:func:`gait_analysis` of a track's evaluation joints at ``fps`` (the capture's frame
    rate). Frames flagged ``failed``, ``missing`` or ``lost`` (:data:`UNUSABLE_FLAGS`) and
    frames absent from the track (gaps in its frame numbers) are invalid; ``options`` are
    :func:`gait_analysis`'s."""
    names = track.meta.get("eval_names")
    if not names:
        raise InputError("gait: the track's track.json names no evaluation joints (eval_names)")
    flags = track.flags or tuple(() if h else ("failed",) for h in track.healthy)
    usable = np.array([not set(f) & set(UNUSABLE_FLAGS) for f in flags], dtype=bool)
    J, extra = _timeline(track.joints, track.frames, usable)
    return gait_analysis(J, fps, names, **extra, **options)


def capture_gait(capture: Capture, *, fps: float | None = None, **options) -> Gait:
    """:func:`gait_analysis` of a synthetic capture's ground-truth joints (``truth/``) at its
    frame rate (or ``fps``); ``options`` are :func:`gait_analysis`'s."""
    truths = [f.truth for f in capture]
    if any(t is None or t.joints is None for t in truths):
        raise InputError(f"gait: the capture {capture.path} has no ground-truth joints")
    names = capture.meta.get("eval_names")
    if not names:
        raise InputError(f"gait: {capture.path / 'capture.json'} names no evaluation joints")
    J = np.stack([t.joints for t in truths])
    J, extra = _timeline(J, np.asarray(capture.indices), np.ones(len(J), bool))
    return gait_analysis(J, capture.fps if fps is None else fps, names, **extra, **options)


def _timeline(J: np.ndarray, frames: np.ndarray, usable: np.ndarray):
    """Joints on a regular timeline of frame numbers (the smallest step between the given
    ones), absent frames invalid: ``(joints, valid=..., frames=...)`` for gait_analysis."""
    frames = np.asarray(frames, dtype=np.int64)
    step = int(np.diff(frames).min()) if len(frames) > 1 else 1
    if step < 1:
        raise InputError("gait: frame numbers must increase")
    pos = (frames - frames[0]) // step
    full = np.full((pos[-1] + 1, *J.shape[1:]), np.nan)
    valid = np.zeros(len(full), bool)
    full[pos], valid[pos] = J, usable
    return full, {"valid": valid, "frames": frames[0] + step * np.arange(len(full))}


@dataclass(frozen=True, eq=False)
class GaitComparison:
    """Gait events and parameters of a test clip (a track) against a reference (its truth).

    Attributes
    ----------
    reference_events : int, foot strikes and foot offs found in the reference
    matched : int, reference events with a test event of the same kind and foot within the
        matching window (each test event matched once, nearest first)
    spurious : int, test events matched to no reference event
    offsets : (m,) float64, frames, test − reference, of the matched events
    cadence_error_pct, stride_length_error_pct : float, (test − reference) / reference × 100
        of the two clips' summaries (NaN where either is missing)
    """

    reference_events: int
    matched: int
    spurious: int
    offsets: np.ndarray
    cadence_error_pct: float
    stride_length_error_pct: float

    @property
    def mean_offset(self) -> float:
        """Mean absolute event offset, frames (NaN without a match)."""
        return float(np.abs(self.offsets).mean()) if len(self.offsets) else float("nan")

    @property
    def max_offset(self) -> float:
        """Largest absolute event offset, frames (NaN without a match)."""
        return float(np.abs(self.offsets).max()) if len(self.offsets) else float("nan")


def compare_gaits(test: Gait, reference: Gait, *, window: float = 0.2) -> GaitComparison:
    """Match the events of ``test`` to those of ``reference`` (same frame numbering and
    frame rate, e.g. a track and its capture's truth) within ``window`` seconds and compare
    their cadence and stride length."""
    if abs(test.fps - reference.fps) > SAME_FPS:
        raise InputError(f"compare_gaits: frame rates differ ({test.fps} and {reference.fps})")
    offsets, n_ref, spurious = [], 0, 0
    for ev in ("strikes", "foot_offs"):
        for k in range(2):
            a = test.frame_numbers(getattr(test, ev)[k])
            b = reference.frame_numbers(getattr(reference, ev)[k])
            d = a[:, None] - b[None, :]
            pairs = sorted(
                zip(*np.nonzero(np.abs(d) <= window * test.fps), strict=True),
                key=lambda ij: abs(d[ij]),
            )
            used_a, used_b = set(), set()
            for i, j in pairs:
                if i not in used_a and j not in used_b:
                    used_a.add(i), used_b.add(j)
                    offsets.append(d[i, j])
            n_ref += len(b)
            spurious += len(a) - len(used_a)

    def err(x: float, y: float) -> float:
        return 100.0 * (x - y) / y if np.isfinite(x) and np.isfinite(y) and y else float("nan")

    s, r = test.summary(), reference.summary()
    return GaitComparison(
        n_ref,
        len(offsets),
        spurious,
        np.asarray(offsets, dtype=float),
        err(s.cadence_steps_per_min, r.cadence_steps_per_min),
        err(s.stride_length_m, r.stride_length_m),
    )
