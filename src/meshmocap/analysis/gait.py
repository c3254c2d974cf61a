"""Gait analysis from tracked joints (cage-manifold-tracking.txt §6.3, Fig. 11): ankle
heights over time, wrists relative to the pelvis in the sagittal plane, gait cycles.

The sagittal plane follows the subject: its forward axis is the horizontal direction of
travel of the pelvis (smoothed over half a second), its up axis is world Z. Gait cycles
run from one contact of the left foot to the next; a contact is the start of a stance
phase, found where the ankle's height is near its clip minimum and its horizontal speed
drops below a threshold.
"""

from __future__ import annotations

import io
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.ndimage import uniform_filter1d

from meshmocap._atomic import write_text_atomic
from meshmocap.errors import InputError

_JOINTS = ("pelvis", "left_ankle", "right_ankle", "left_wrist", "right_wrist")


@dataclass(frozen=True, eq=False)
class Gait:
    """Gait curves of a clip.

    Attributes
    ----------
    times : (T,) float64, seconds
    ankle_height : (T, 2) float64, left and right ankle heights above the lowest one, metres
    wrist_sagittal : (T, 2, 2) float64, left/right wrist (forward, up) relative to the pelvis
        in the sagittal plane, metres
    contacts : tuple of two (k,) int64 arrays, frames where the left/right foot lands
    cycles : (c, 2) int64, [start, end) frames of the left-foot gait cycles
    """

    times: np.ndarray
    ankle_height: np.ndarray
    wrist_sagittal: np.ndarray
    contacts: tuple[np.ndarray, np.ndarray]
    cycles: np.ndarray

    @property
    def cadence(self) -> float:
        """Steps per minute from the detected cycles (NaN without a full cycle)."""
        if len(self.cycles) == 0:
            return float("nan")
        dt = np.diff(self.times[self.cycles], axis=1).mean()
        return float(120.0 / dt)


def gait_analysis(
    joints: np.ndarray,
    fps: float,
    names: tuple[str, ...] | list[str],
    *,
    contact_height: float = 0.03,
    contact_speed: float = 0.25,
) -> Gait:
    """Compute gait curves and cycles from evaluation-joint trajectories.

    Parameters
    ----------
    joints : (T, K, 3) float64
        Joint positions, metres, world frame (Z up).
    fps : float
        Frames per second.
    names : sequence of K str
        Joint names; needs pelvis, left/right ankle and wrist.
    contact_height : float
        Metres above the ankle's lowest height that still count as on the ground.
    contact_speed : float
        Horizontal ankle speed (m/s) below which a foot is planted.
    """
    J = np.asarray(joints, dtype=float)
    if J.ndim != 3 or J.shape[2] != 3 or len(J) < 3:
        raise InputError(f"gait: joints must have shape (T ≥ 3, K, 3), found {J.shape}")
    missing = [n for n in _JOINTS if n not in names]
    if missing:
        raise InputError(f"gait: joints {missing} are missing from {list(names)}")
    if not np.all(np.isfinite(J)):
        raise InputError("gait: joints contain NaN or infinite values")
    idx = {n: list(names).index(n) for n in _JOINTS}
    pelvis = J[:, idx["pelvis"]]
    ankles = J[:, [idx["left_ankle"], idx["right_ankle"]]]
    wrists = J[:, [idx["left_wrist"], idx["right_wrist"]]]
    times = np.arange(len(J)) / fps
    height = ankles[..., 2] - ankles[..., 2].min()
    # sagittal frame: forward = smoothed horizontal pelvis velocity
    v = np.gradient(pelvis[:, :2], axis=0) * fps
    v = uniform_filter1d(v, size=max(1, round(0.5 * fps)), axis=0, mode="nearest")
    speed = np.linalg.norm(v, axis=1, keepdims=True)
    fwd = np.where(speed > 1e-3, v / np.maximum(speed, 1e-12), [0.0, -1.0])  # at rest: facing −Y
    rel = wrists - pelvis[:, None]
    wrist = np.stack([np.einsum("tkj,tj->tk", rel[..., :2], fwd), rel[..., 2]], axis=-1)
    foot_speed = np.linalg.norm(np.gradient(ankles[..., :2], axis=0), axis=-1) * fps
    planted = (height < contact_height) & (foot_speed < contact_speed)
    contacts = tuple(np.flatnonzero(p[1:] & ~p[:-1]) + 1 for p in planted.T)
    left = contacts[0]
    cycles = (
        np.stack([left[:-1], left[1:]], axis=1) if len(left) > 1 else np.zeros((0, 2), np.int64)
    )
    return Gait(times, height, wrist, contacts, cycles)  # type: ignore[arg-type]


def write_gait_csv(path: str | os.PathLike, gait: Gait) -> Path:
    """Write the gait curves, one row per frame, atomically."""
    head = ("time_s,left_ankle_height_m,right_ankle_height_m,left_wrist_forward_m,left_wrist_up_m,"
            "right_wrist_forward_m,right_wrist_up_m,left_contact,right_contact")  # fmt: skip
    frames = np.arange(len(gait.times))
    contact = [np.isin(frames, c).astype(float) for c in gait.contacts]
    table = np.column_stack(
        [gait.times, gait.ankle_height, gait.wrist_sagittal.reshape(-1, 4), *contact]
    )
    buf = io.StringIO()
    np.savetxt(
        buf,
        table,
        fmt=["%.4f"] + ["%.5f"] * 6 + ["%d"] * 2,
        delimiter=",",
        header=head,
        comments="",
    )
    write_text_atomic(path, buf.getvalue())
    return Path(path)
