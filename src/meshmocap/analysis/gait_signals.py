"""Signals of a gait (:mod:`meshmocap.analysis.gait`): smoothing, stance runs, event
timing, the subject's forward direction and flexion angles in the sagittal plane.

Pure array functions; the protocol they implement is stated in :mod:`meshmocap.analysis.gait`.

References
----------
- A. Savitzky, M. J. E. Golay, *Smoothing and differentiation of data by
  simplified least squares procedures*, Analytical Chemistry 36(8):1627–1639, 1964.
  https://doi.org/10.1021/ac60214a047
"""

from __future__ import annotations

import numpy as np
from scipy.ndimage import uniform_filter1d
from scipy.signal import savgol_filter

from meshmocap._tolerances import NORM_FLOOR

SIDES = ("left", "right")


def runs(mask: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Starts and (exclusive) ends of the runs of True in a 1-D bool array."""
    d = np.diff(np.concatenate([[0], mask.astype(np.int8), [0]]))
    return np.flatnonzero(d == 1), np.flatnonzero(d == -1)


def close_gaps(mask: np.ndarray, n: int) -> np.ndarray:
    """Fill runs of False shorter than ``n`` that lie between two runs of True."""
    out = mask.copy()
    starts, ends = runs(~mask)
    for s, e in zip(starts, ends, strict=True):
        if s > 0 and e < len(mask) and e - s < n:
            out[s:e] = True
    return out


def drop_short(mask: np.ndarray, n: int) -> np.ndarray:
    """Clear runs of True shorter than ``n`` (runs touching an end of the clip are kept:
    they may continue outside it)."""
    out = mask.copy()
    starts, ends = runs(mask)
    for s, e in zip(starts, ends, strict=True):
        if e - s < n and s > 0 and e < len(mask):
            out[s:e] = False
    return out


def fill_invalid(X: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """Linear interpolation over time of the rows of ``X`` (T, ...) where ``valid`` is False."""
    if valid.all():
        return X
    t = np.arange(len(X))
    flat = X.reshape(len(X), -1)
    out = np.empty_like(flat)
    for c in range(flat.shape[1]):  # a few dozen columns
        out[:, c] = np.interp(t, t[valid], flat[valid, c])
    return out.reshape(X.shape)


def smoothed(X: np.ndarray, window: int, deriv: int = 0) -> np.ndarray:
    """Savitzky–Golay smoothing (quadratic) along time (axis 0); ``window`` odd ≥ 5, or
    ≤ 1 for none (a central difference for ``deriv=1``)."""
    if window <= 1 or len(X) < window:
        return np.gradient(X, axis=0) if deriv else X
    return savgol_filter(X, window, 2, deriv=deriv, axis=0, mode="interp")


def unit(v: np.ndarray) -> np.ndarray:
    """Return ``v`` (..., 3) scaled to unit length along the last axis (zero stays zero)."""
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    return v / np.maximum(n, NORM_FLOOR)


def forward(J: np.ndarray, idx: dict[str, int], fps: float) -> np.ndarray:
    """(T, 3) unit forward directions (horizontal): perpendicular to the right → left hip
    line, smoothed over one second."""
    lateral = J[:, idx["left_hip"]] - J[:, idx["right_hip"]]
    lateral[:, 2] = 0.0
    lateral = uniform_filter1d(unit(lateral), size=max(1, round(fps)), axis=0, mode="nearest")
    return unit(np.cross(lateral, [0.0, 0.0, 1.0]))


def sagittal_angle(a: np.ndarray, b: np.ndarray, fwd: np.ndarray) -> np.ndarray:
    """Signed angle (degrees) from ``a`` to ``b`` (T, 3), both projected on the sagittal
    plane (forward, up), counter-clockwise in those coordinates: for vectors pointing down,
    positive when ``b`` points further forward than ``a`` (a thigh in front of the trunk)."""
    af, az = np.einsum("tj,tj->t", a, fwd), a[:, 2]
    bf, bz = np.einsum("tj,tj->t", b, fwd), b[:, 2]
    return np.degrees(np.arctan2(af * bz - az * bf, af * bf + az * bz))


def flexion_angles(
    joints: np.ndarray, names: tuple[str, ...] | list[str], fwd: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Hip and knee flexion of both legs in the sagittal plane (module docstring).

    Parameters
    ----------
    joints : (T, K, 3) float64, metres, world frame (Z up)
    names : K joint names (pelvis, thorax, left/right hip, knee, ankle)
    fwd : (T, 3) float64, unit horizontal forward directions of the subject

    Returns
    -------
    hip, knee : (T, 2) float64, degrees, left and right
    """
    need = ("pelvis", "thorax", *(f"{s}_{j}" for s in SIDES for j in ("hip", "knee", "ankle")))
    idx = {n: list(names).index(n) for n in need}
    down = joints[:, idx["pelvis"]] - joints[:, idx["thorax"]]
    hip, knee = [], []
    for s in SIDES:
        thigh = joints[:, idx[f"{s}_knee"]] - joints[:, idx[f"{s}_hip"]]
        shank = joints[:, idx[f"{s}_ankle"]] - joints[:, idx[f"{s}_knee"]]
        hip.append(sagittal_angle(down, thigh, fwd))
        knee.append(-sagittal_angle(thigh, shank, fwd))
    return np.stack(hip, axis=1), np.stack(knee, axis=1)


def crossing(x0: float, x1: float, level: float) -> float:
    """Fraction in [0, 1] of the way from x0 to x1 where the line crosses ``level``."""
    d = x1 - x0
    return float(np.clip((level - x0) / d, 0.0, 1.0)) if d != 0 else 0.5


def stance_mask(
    speed: np.ndarray, low: np.ndarray, strike_speed: float, off_speed: float
) -> np.ndarray:
    """(T,) bool, where a foot is planted: runs of frames that are ``low`` and slower than
    both speeds, each extended backwards while slower than ``strike_speed`` (the stance
    starts where the landing foot slows below it) and forwards while slower than
    ``off_speed`` (it ends where the foot speeds up past it), still ``low``."""
    out = (speed < min(strike_speed, off_speed)) & low
    starts, ends = runs(out)
    T = len(speed)
    for s, e in zip(starts, ends, strict=True):
        while s > 0 and low[s - 1] and speed[s - 1] < strike_speed:
            s -= 1
        while e < T and low[e] and speed[e] < off_speed:
            e += 1
        out[s:e] = True
    return out


def stance_events(
    planted: np.ndarray,
    speed: np.ndarray,
    height: np.ndarray,
    strike_speed: float,
    off_speed: float,
    gate: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Stance runs (starts, exclusive ends) of ``planted`` and the fractional positions of
    their strikes and foot offs (NaN at a clip end): where the speed crosses
    ``strike_speed`` before a stance and ``off_speed`` after it, or the height crosses
    ``gate`` (the later crossing before, the earlier after)."""
    starts, ends = runs(planted)
    T = len(planted)
    strikes = np.full(len(starts), np.nan)
    offs = np.full(len(starts), np.nan)
    for k, (s, e) in enumerate(zip(starts, ends, strict=True)):
        if s > 0:  # frame s−1 fails a condition that frame s meets: the later crossing
            pairs = ((speed, strike_speed), (height, gate))
            fr = [crossing(x[s - 1], x[s], lv) if x[s - 1] >= lv else 0.0 for x, lv in pairs]
            strikes[k] = s - 1 + max(fr)
        if e < T:  # frame e−1 meets both, frame e fails one: the earlier crossing
            pairs = ((speed, off_speed), (height, gate))
            fr = [crossing(x[e - 1], x[e], lv) if x[e] >= lv else 1.0 for x, lv in pairs]
            offs[k] = e - 1 + min(fr)
    return starts, ends, strikes, offs


def event_usable(pos: float, bad: np.ndarray, *, end_margin: int = 2, bad_margin: int = 2) -> bool:
    """Whether an event at frame position ``pos`` lies at least ``end_margin`` frames inside
    the clip and ``bad_margin`` frames away from unusable ones (``bad``: (T,) bool)."""
    if not np.isfinite(pos) or pos < end_margin or pos > len(bad) - 1 - end_margin:
        return False
    lo = max(0, int(np.floor(pos)) - bad_margin)
    return not bad[lo : int(np.ceil(pos)) + bad_margin + 1].any()
