"""Joint trajectories as CSV (pandas, spreadsheets): wide (one row per frame) or long (one
row per frame and joint).

Conventions of the files written here:

* Comma-separated, a header row, ``\\n`` line endings, UTF-8; numbers with 6 decimals
  (micrometres); never NaN or empty numeric cells.
* Coordinates in **metres**, the library's world frame: **Z up**, right-handed (subject
  facing −Y at rest, left side towards +X).
* Per-frame columns: ``frame`` (capture frame number), ``time_s`` (frame / fps),
  ``healthy`` (1/0), one 0/1 column per frame flag (:data:`FLAG_COLUMNS`, see
  :data:`meshmocap.io.results.FRAME_FLAGS`) and ``message`` (why a frame is flagged; may
  be empty).
* Wide: then ``<joint>_x, <joint>_y, <joint>_z`` per joint. Long: ``joint, x, y, z``.
"""

from __future__ import annotations

import csv
import io
import os
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from meshmocap._atomic import write_text_atomic
from meshmocap.errors import InputError
from meshmocap.io.results import FRAME_FLAGS

__all__ = ["FLAG_COLUMNS", "write_joints_csv"]

#: The frame-flag columns (0/1), in order.
FLAG_COLUMNS = FRAME_FLAGS


def write_joints_csv(
    path: str | os.PathLike,
    joints: np.ndarray,
    names: Sequence[str],
    frames: np.ndarray,
    fps: float,
    *,
    healthy: np.ndarray | None = None,
    flags: Sequence[Sequence[str]] | None = None,
    messages: Sequence[str] | None = None,
    long: bool = False,
    valid: np.ndarray | None = None,
) -> Path:
    """Write joint trajectories as CSV, atomically; return the path.

    Parameters
    ----------
    joints : (T, K, 3) float64
        Metres, world frame (Z up); finite.
    names : sequence of K str
        Joint names.
    frames : (T,) int
        Capture frame numbers.
    fps : float
        Frame rate (``time_s = frame / fps``).
    healthy : (T,) bool, optional (default all True)
    flags : T sequences of str from FRAME_FLAGS, optional; messages : T str, optional
    long : bool
        One row per frame and joint instead of one per frame.
    valid : (T,) bool, optional
        False marks a gap: the frame's coordinate cells are left empty.
    """
    X = np.asarray(joints, dtype=np.float64)
    if X.ndim != 3 or X.shape[2] != 3 or X.shape[0] == 0:
        raise InputError(f"write_joints_csv: joints must have shape (T, K, 3), found {X.shape}")
    if not np.all(np.isfinite(X)):
        raise InputError("write_joints_csv: joints contain NaN or infinite values")
    T, K = X.shape[:2]
    if len(names) != K:
        raise InputError(f"write_joints_csv: expected {K} joint names, found {len(names)}")
    idx = np.asarray(frames, dtype=np.int64)
    if idx.shape != (T,):
        raise InputError(f"write_joints_csv: expected {T} frame numbers, found {idx.shape}")
    if not (np.isfinite(fps) and fps > 0):
        raise InputError(f"write_joints_csv: fps must be a positive number, found {fps!r}")
    ok = np.ones(T, bool) if healthy is None else np.asarray(healthy, dtype=bool)
    fl = [()] * T if flags is None else [tuple(f) for f in flags]
    msg = [""] * T if messages is None else [str(m) for m in messages]
    has = np.ones(T, bool) if valid is None else np.asarray(valid, dtype=bool)
    if ok.shape != (T,) or has.shape != (T,) or len(fl) != T or len(msg) != T:
        raise InputError(
            f"write_joints_csv: healthy, valid, flags and messages need {T} entries each"
        )
    head = ["frame", "time_s", "healthy", *FLAG_COLUMNS, "message"]
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    if long:
        w.writerow([*head, "joint", "x", "y", "z"])
    else:
        w.writerow([*head, *(f"{n}_{a}" for n in names for a in "xyz")])
    for t in range(T):
        lead = [int(idx[t]), f"{idx[t] / fps:.6f}", int(ok[t])]
        lead += [int(f in fl[t]) for f in FLAG_COLUMNS] + [msg[t]]
        cells = [f"{v:.6f}" if has[t] else "" for v in X[t].ravel()]
        if long:
            for k in range(K):
                w.writerow([*lead, names[k], *cells[3 * k : 3 * k + 3]])
        else:
            w.writerow([*lead, *cells])
    write_text_atomic(path, buf.getvalue())
    return Path(path)
