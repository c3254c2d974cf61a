"""C3D motion files (biomechanics: Vicon Nexus, Visual3D, Mokka), through ezc3d.

Conventions of the files written here:

* Labelled 3D points in **millimetres** (``POINT:UNITS = mm``), in the library's world
  frame: **Z up**, right-handed, the usual frame of C3D files from optical systems (the
  subject faces −Y at rest, its left side towards +X).
* ``POINT:RATE`` is the frame rate; the header's first frame is the first frame's number
  in the capture (C3D counts from 1, so frame 0 is written as 1).
* Each point's residual is 0 for a valid sample and −1 for an invalid one (the C3D
  convention for a gap); readers such as ezc3d then give NaN for that sample.

References
----------
- Motion Lab Systems, *The C3D file format user guide*, https://www.c3d.org.
- B. Michaud, M. Begon, *ezc3d: an easy C3D file I/O cross-platform solution for
  C++, Python and MATLAB*, Journal of Open Source Software 6(58):2911, 2021.
  https://doi.org/10.21105/joss.02911
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from meshmocap.errors import FormatError, InputError, MeshmocapFileNotFoundError
from meshmocap.io._labelled import labelled_points, valid_mask

__all__ = ["C3dPoints", "read_c3d", "write_c3d"]


@dataclass(frozen=True, eq=False)
class C3dPoints:
    """Labelled points read from a C3D file.

    Attributes
    ----------
    labels : tuple of str, length P
    points : (T, P, 3) float64, metres, the file's frame (NaN where a sample is invalid)
    fps : float
    first_frame : int, number of the first frame, counted from 0
    """

    labels: tuple[str, ...]
    points: np.ndarray
    fps: float
    first_frame: int


def _check_points(func: str, points, labels, fps, valid) -> tuple[np.ndarray, np.ndarray]:
    X, _ = labelled_points(func, points, labels, fps)
    return X, valid_mask(func, X, valid)


def write_c3d(
    path: str | os.PathLike,
    points: np.ndarray,
    labels: Sequence[str],
    fps: float,
    *,
    first_frame: int = 0,
    valid: np.ndarray | None = None,
    descriptions: Sequence[str] | None = None,
) -> Path:
    """Write labelled points as a C3D file, atomically; return the path.

    Parameters
    ----------
    points : (T, P, 3) float64
        Metres, world frame (Z up); finite.
    labels : sequence of P str
        Point labels (distinct).
    fps : float
        Frame rate.
    first_frame : int
        Capture number of the first frame, counted from 0 (written as ``first_frame + 1``).
    valid : (T,) or (T, P) bool, optional
        False marks a sample invalid, a gap: residual −1 and coordinates 0.
    descriptions : sequence of P str, optional
        ``POINT:DESCRIPTIONS``.
    """
    import ezc3d

    X, ok = _check_points("write_c3d", points, labels, fps, valid)
    path = Path(path)
    if not path.parent.is_dir():
        raise MeshmocapFileNotFoundError(f"{path}: folder {path.parent} does not exist")
    if int(first_frame) < 0:
        raise InputError(f"write_c3d: first_frame must be ≥ 0, found {first_frame}")
    T, P = X.shape[:2]
    c = ezc3d.c3d()
    c["parameters"]["POINT"]["RATE"]["value"] = [float(fps)]
    c["parameters"]["POINT"]["LABELS"]["value"] = [str(s) for s in labels]
    c["parameters"]["POINT"]["DESCRIPTIONS"]["value"] = (
        [str(s) for s in descriptions] if descriptions is not None else [""] * P
    )
    c["parameters"]["POINT"]["UNITS"]["value"] = ["mm"]
    data = np.ones((4, P, T))
    data[:3] = (np.where(ok[..., None], X, 0.0) * 1000.0).transpose(2, 1, 0)  # gaps: 0
    c["data"]["points"] = data
    c["data"]["meta_points"]["residuals"] = np.where(ok.T, 0.0, -1.0)[None]
    c.add_parameter("TRIAL", "ACTUAL_START_FIELD", [int(first_frame) + 1, 0])
    c.add_parameter("TRIAL", "ACTUAL_END_FIELD", [int(first_frame) + T, 0])
    c["header"]["points"]["first_frame"] = int(first_frame)
    tmp = path.with_name(f".{path.stem}.{os.getpid()}.tmp.c3d")  # ezc3d wants .c3d
    try:
        c.write(str(tmp))
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)
    return path


def read_c3d(path: str | os.PathLike) -> C3dPoints:
    """Read the labelled points of a C3D file (metres; invalid samples NaN)."""
    import ezc3d

    path = Path(path)
    if not path.is_file():
        raise MeshmocapFileNotFoundError(f"{path}: no such C3D file")
    try:
        c = ezc3d.c3d(str(path))
    except (RuntimeError, ValueError, OSError) as exc:
        raise FormatError(f"{path}: not a readable C3D file ({exc})") from None
    unit = str((c["parameters"]["POINT"].get("UNITS", {}).get("value") or ["mm"])[0]).strip()
    scale = {"mm": 1e-3, "cm": 1e-2, "m": 1.0}.get(unit)
    if scale is None:
        raise FormatError(f"{path}: unsupported POINT:UNITS {unit!r} (expected mm, cm or m)")
    X = np.asarray(c["data"]["points"][:3], dtype=np.float64).transpose(2, 1, 0) * scale
    return C3dPoints(
        tuple(str(s) for s in c["parameters"]["POINT"]["LABELS"]["value"]),
        X,
        float(c["parameters"]["POINT"]["RATE"]["value"][0]),
        int(c["header"]["points"]["first_frame"]),
    )
