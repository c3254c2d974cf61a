"""The up axis, the units and the whereabouts of a mesh or point-cloud capture, read from
its first frame, or a refusal that names the option to set.

* **Units.** A person (standing, crouching, arms up) spans 0.4–3 m along their longest
  extent; the same body in centimetres spans 40–300 units and in millimetres 400–3000.
  A span in none of these ranges is refused (``--units``).
* **Up axis.** Most of a person's surface lies along the vertical (legs, trunk, head: the
  arms of a T-pose are a small part of it), so the principal axis of the points is
  vertical. It must lie within :data:`MAX_TILT` of a file axis, and stand out from the
  other principal axes (variance ratio :data:`MIN_ELONGATION`), else the file is refused
  (``--up``). The sign is not read: a Y-up file is taken as +Y up.
* **Far away.** Track files store vertices in single precision, which keeps a millimetre
  only within :data:`MAX_DISTANCE` of the origin: a body farther away is refused with the
  distance (move the files' origin into the capture volume).

Everything returned is about the files' raw coordinates.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from meshmocap._tolerances import SAME_FPS
from meshmocap.errors import FormatError, InputError, MeshError, MeshmocapFileNotFoundError
from meshmocap.io.capture import Capture, SequenceCapture, open_capture

__all__ = [
    "MAX_DISTANCE",
    "MAX_TILT",
    "MIN_ELONGATION",
    "UNITS",
    "Axes",
    "detect_axes",
    "open_oriented",
]

#: Metres per unit of each accepted unit.
UNITS: dict[str, float] = {"m": 1.0, "cm": 0.01, "mm": 0.001}
#: Longest extent of a person, metres.
PERSON_SPAN = (0.4, 3.0)
#: Largest angle (degrees) between the principal axis and the file axis taken as up.
MAX_TILT = 35.0
#: Least ratio of the largest principal variance to the second.
MIN_ELONGATION = 1.5
#: Metres from the origin within which float32 track files keep a millimetre (2⁻²³ · d).
MAX_DISTANCE = 8000.0


@dataclass(frozen=True)
class Axes:
    """What :func:`detect_axes` read from a frame.

    Attributes
    ----------
    up : {"z", "y"}, the files' up axis
    units : {"m", "cm", "mm"}, the files' length unit
    span : float, the body's longest extent in metres
    """

    up: str
    units: str
    span: float


def detect_axes(
    X: np.ndarray, *, up: str = "auto", units: str = "auto", source: str = "capture"
) -> Axes:
    """Detect (or check) the up axis and units of a frame's raw points.

    Parameters
    ----------
    X : (p, 3) float64
        The first frame's vertices or points as stored in the files (no conversion).
    up : {"auto", "z", "y"}
        Given by the user (checked only for the far-away case), or detected.
    units : {"auto", "m", "cm", "mm"}
        Given by the user, or detected.
    source : str
        Named in the messages.

    Raises
    ------
    InputError
        One line naming the flag to set (``--up``, ``--units``), or the distance of a body
        too far from the origin.
    """
    X = np.asarray(X, dtype=np.float64)
    X = X[np.all(np.isfinite(X), axis=1)]
    if len(X) < 10:
        raise InputError(f"track: {source}: the first frame has {len(X)} points; no body to read")
    span = float(np.max(np.ptp(X, axis=0)))
    if units == "auto":
        fits = [u for u, s in UNITS.items() if PERSON_SPAN[0] <= span * s <= PERSON_SPAN[1]]
        if len(fits) != 1:
            raise InputError(
                f"track: {source}: the body spans {span:.4g} file units, not a person in "
                f"metres, centimetres or millimetres; set --units (m, cm or mm)"
            )
        units = fits[0]
    scale = UNITS[units]
    far = float(np.linalg.norm(X.mean(axis=0))) * scale
    if far > MAX_DISTANCE:
        raise InputError(
            f"track: {source}: the body stands {far / 1000:.0f} km from the origin; track files "
            f"keep a millimetre only within {MAX_DISTANCE / 1000:.0f} km: move the files' "
            "origin into the capture volume"
        )
    if up == "auto":
        Y = X - X.mean(axis=0)
        w, U = np.linalg.eigh(Y.T @ Y)
        axis = np.abs(U[:, -1])
        k = int(np.argmax(axis))
        tilt = float(np.degrees(np.arccos(min(axis[k], 1.0))))
        if w[-1] < MIN_ELONGATION * w[-2] or tilt > MAX_TILT or k == 0:
            raise InputError(
                f"track: {source}: cannot tell the up axis (the body's long axis is "
                f"{tilt:.0f}° from {'xyz'[k]}); set --up (z or y)"
            )
        up = "yz"[k - 1]
    return Axes(up, units, span * scale)


def open_oriented(
    source, *, up: str = "auto", units: str = "auto", fps: float | None = None
) -> tuple[Capture | SequenceCapture, Axes | None]:
    """Open a capture (:func:`~meshmocap.io.capture.open_capture`) in metres, Z up.

    A capture folder is metres and Z up by its format (``up``/``units`` other than
    ``"auto"`` are refused), its frame rate that of its ``capture.json`` (a different
    ``fps`` is refused). A mesh or point-cloud sequence has its up axis and units
    detected from its first frame (:func:`detect_axes`) where not given, its frame rate
    ``fps`` (default 30).

    Returns
    -------
    capture, and the :class:`Axes` read (None for a capture folder).
    """
    for name, value, choices in (
        ("up", up, ("auto", "z", "y")),
        ("units", units, ("auto", *UNITS)),
    ):
        if value not in choices:
            raise InputError(f"track: --{name} must be one of {list(choices)}, found {value!r}")
    raw = open_capture(source)
    if isinstance(raw, Capture):
        if up not in ("auto", "z") or units not in ("auto", "m"):
            raise InputError(
                f"track: {source} is a capture folder: metres, Z up; "
                "--up and --units apply to mesh and point-cloud files"
            )
        said = raw.meta.get("fps")
        if fps is not None and said is not None and abs(float(said) - fps) > SAME_FPS:
            raise InputError(
                f"track: {source} is a capture folder of {said:g} fps (capture.json); "
                "--fps applies to mesh and point-cloud files"
            )
        if fps is not None and said is None:
            raw.meta["fps"] = float(fps)
        return raw, None
    axes = detect_axes(_first_readable(raw, source), up=up, units=units, source=str(source))
    return SequenceCapture(source, up=axes.up, scale=UNITS[axes.units], fps=fps), axes


def _first_readable(raw: SequenceCapture, source) -> np.ndarray:
    """The raw vertices of the sequence's first frame that can be read (an unreadable or
    empty frame is the driver's ``missing`` frame, not a reason to refuse the sequence)."""
    first = None
    for k in range(len(raw.seq)):
        try:
            V = raw.seq[k].V
        except (MeshmocapFileNotFoundError, FormatError, MeshError) as exc:
            first = first or f"{exc}".splitlines()[0]
            continue
        if len(V) >= 10:
            return V
    raise InputError(f"track: no frame of {source} has a body to read ({first or 'no points'})")
