"""TRC marker files (OpenSim, Pose2Sim): labelled 3D points as tab-separated text.

Conventions of the files written here (OpenSim's):

* **Millimetres** (``Units mm``), **Y up** in OpenSim's body frame: X forward, Y up,
  Z to the subject's right. The library's Z-up world (subject facing −Y, left towards +X)
  is turned by (x, y, z) → (−y, z, −x) (:data:`Z_UP_TO_OPENSIM`), so a subject in its rest
  heading faces +X as OpenSim's models do.
* Header: ``PathFileType 4 (X/Y/Z) name``, then ``DataRate CameraRate NumFrames
  NumMarkers Units OrigDataRate OrigDataStartFrame OrigNumFrames``, then the marker names
  (each over three columns) and ``X1 Y1 Z1 X2 ...``, then an empty line.
* Rows: ``Frame#`` (1, 2, ...), ``Time`` (seconds from the capture's start), then the
  coordinates with 6 decimals. ``OrigDataStartFrame`` is the capture's number of the
  first frame, counted from 1.
* A gap (a marker without a value on a frame: ``valid`` False) is written as three empty
  cells, as OpenSim and Pose2Sim read missing markers; :func:`read_trc` gives NaN there.

References
----------
- S. L. Delp, F. C. Anderson, A. S. Arnold, P. Loan, A. Habib, C. T. John,
  E. Guendelman, D. G. Thelen, *OpenSim: open-source software to create and analyze
  dynamic simulations of movement*, IEEE Transactions on Biomedical Engineering
  54(11):1940–1950, 2007. https://doi.org/10.1109/TBME.2007.901024
- D. Pagnon, M. Domalain, L. Reveret, *Pose2Sim: an open-source Python package for
  multiview markerless kinematics*, Journal of Open Source Software, 2022.
  https://doi.org/10.21105/joss.04362
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from meshmocap._atomic import write_text_atomic
from meshmocap.errors import FormatError, InputError, MeshmocapFileNotFoundError
from meshmocap.io._labelled import labelled_points, valid_mask

__all__ = ["Z_UP_TO_OPENSIM", "TrcMarkers", "read_trc", "write_trc"]

#: Rotation from the library's Z-up world to OpenSim's frame: (x, y, z) → (−y, z, −x).
Z_UP_TO_OPENSIM = np.array([[0.0, -1.0, 0.0], [0.0, 0.0, 1.0], [-1.0, 0.0, 0.0]])


@dataclass(frozen=True, eq=False)
class TrcMarkers:
    """Markers read from a TRC file.

    Attributes
    ----------
    labels : tuple of str, length P
    points : (T, P, 3) float64, metres, world frame (Z up; converted back from OpenSim's)
    fps : float
    times : (T,) float64, seconds
    first_frame : int, ``OrigDataStartFrame`` counted from 0
    """

    labels: tuple[str, ...]
    points: np.ndarray
    fps: float
    times: np.ndarray
    first_frame: int


def write_trc(
    path: str | os.PathLike,
    points: np.ndarray,
    labels: Sequence[str],
    fps: float,
    *,
    first_frame: int = 0,
    start_time: float = 0.0,
    valid: np.ndarray | None = None,
) -> Path:
    """Write labelled points as a TRC file, atomically; return the path.

    Parameters
    ----------
    points : (T, P, 3) float64
        Metres, world frame (Z up); finite.
    labels : sequence of P str
        Marker names: distinct, without tabs or line breaks.
    fps : float
        Frame rate.
    first_frame : int
        Capture number of the first frame, counted from 0.
    start_time : float
        Time of the first frame, seconds (the others follow at ``1 / fps``).
    valid : (T,) or (T, P) bool, optional
        False marks a gap: the marker has no value on that frame (empty cells).
    """
    X, labels = labelled_points("write_trc", points, labels, fps)
    T, P = X.shape[:2]
    ok = valid_mask("write_trc", X, valid)
    if int(first_frame) < 0 or not np.isfinite(start_time):
        raise InputError(f"write_trc: first_frame must be ≥ 0, found {first_frame}")
    path = Path(path)
    if not path.parent.is_dir():
        raise MeshmocapFileNotFoundError(f"{path}: folder {path.parent} does not exist")
    Y = (X @ Z_UP_TO_OPENSIM.T * 1000.0).reshape(T, 3 * P)
    head = [
        f"PathFileType\t4\t(X/Y/Z)\t{path.name}",
        "DataRate\tCameraRate\tNumFrames\tNumMarkers\tUnits\tOrigDataRate\t"
        "OrigDataStartFrame\tOrigNumFrames",
        f"{fps:g}\t{fps:g}\t{T}\t{P}\tmm\t{fps:g}\t{int(first_frame) + 1}\t{T}",
        "Frame#\tTime\t" + "\t".join(f"{s}\t\t" for s in labels).rstrip("\t"),
        "\t\t" + "\t".join(f"X{k}\tY{k}\tZ{k}" for k in range(1, P + 1)),
        "",
    ]
    cells = np.char.mod("%.6f", Y)
    cells[~np.repeat(ok, 3, axis=1)] = ""
    lead = [f"{k + 1}\t{start_time + k / fps:.6f}" for k in range(T)]
    rows = "\n".join(a + "\t" + "\t".join(c) for a, c in zip(lead, cells, strict=True))
    write_text_atomic(path, "\n".join(head) + "\n" + rows + "\n")
    return path


def read_trc(path: str | os.PathLike) -> TrcMarkers:
    """Read a TRC file written in millimetres or metres (as :func:`write_trc` writes it,
    or by other tools with the same header), back to metres in the Z-up world frame; a gap
    (empty cells) reads as NaN."""
    path = Path(path)
    if not path.is_file():
        raise MeshmocapFileNotFoundError(f"{path}: no such TRC file")
    lines = path.read_text(encoding="utf-8", errors="replace").splitlines()
    if len(lines) < 5 or not lines[0].startswith("PathFileType"):
        raise FormatError(f"{path}:1: expected a TRC header starting with PathFileType")
    keys, values = lines[1].split("\t"), lines[2].split("\t")
    info = dict(zip([k.strip() for k in keys], [v.strip() for v in values], strict=False))
    try:
        fps = float(info["DataRate"])
        first = int(info.get("OrigDataStartFrame", "1")) - 1
        n_markers = int(info["NumMarkers"])
        scale = {"mm": 1e-3, "m": 1.0, "cm": 1e-2}[info.get("Units", "mm")]
    except (KeyError, ValueError):
        raise FormatError(f"{path}:3: unreadable TRC header values {values}") from None
    labels = tuple(s.strip() for s in lines[3].split("\t")[2:] if s.strip())
    if len(labels) != n_markers:
        raise FormatError(f"{path}:4: NumMarkers is {n_markers}, found {len(labels)} names")
    rows = [ln.split("\t") for ln in lines[5:] if ln.strip()]
    try:
        table = np.array(
            [[float(x) if x.strip() else np.nan for x in r[: 2 + 3 * n_markers]] for r in rows]
        )
    except ValueError as exc:
        raise FormatError(f"{path}: unreadable number in the data ({exc})") from None
    if table.ndim != 2 or table.shape[1] != 2 + 3 * n_markers:
        raise FormatError(f"{path}: expected {2 + 3 * n_markers} columns per row")
    X = table[:, 2:].reshape(len(table), n_markers, 3) * scale @ Z_UP_TO_OPENSIM
    return TrcMarkers(labels, X, fps, table[:, 1], first)
