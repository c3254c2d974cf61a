"""How a track's first pose was found, as a record: :class:`Start`.

A start is a decision (where tracking begins, and whether that is trusted) that several
parts need: the driver flags an uncertain start's frame ``lost``, the capture cache keeps
a searched start, ``track.json`` records it (:func:`~meshmocap.io.results.write_start`)
and the evaluation and the reports read it back
(:func:`~meshmocap.io.results.read_start`). It travels as this record; the first frame's
message is made from it (:func:`~meshmocap.estimate.pose.start.start_message`) and never
read back.

:func:`start_json` and :func:`start_of_json` convert it to and from plain JSON values:
``float`` written by ``json`` is the shortest text that reads back to the same
``float64``, so the pose comes back bit for bit.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal, get_args

import numpy as np

from meshmocap.errors import FormatError, InputError

__all__ = ["START_SOURCES", "Start", "StartSource", "start_json", "start_of_json"]

#: Where a track's first pose came from:
#:
#: * ``search``: the global search of the frame alone (``init="auto"``,
#:   :func:`~meshmocap.estimate.pose.first_pose.initial_pose`);
#: * ``truth``: the frame's ground-truth pose (``init="truth"``, the papers' protocol);
#: * ``rest``: the template is this frame itself (``init="truth"`` on a capture whose truth
#:   is the template's own rest mesh, a template cut from the frame): its rest pose;
#: * ``subject-rest``: the template was rigged from this frame as it stands (a clean 4D
#:   capture, :mod:`~meshmocap.estimate.performer.tracking_template`): its rest pose;
#: * ``subject-fit``: the template's body was fitted to this frame's points or silhouettes:
#:   the pose fitted with it.
StartSource = Literal["search", "truth", "rest", "subject-rest", "subject-fit"]
START_SOURCES: tuple[str, ...] = get_args(StartSource)


@dataclass(frozen=True, eq=False)
class Start:
    """Where a track starts and how that pose was found.

    Attributes
    ----------
    frame : int, the frame number the pose is of
    R : (J, 3, 3) float64, local rotations of the template's skeleton
    root : (3,) float64, root position, metres, world frame (Z up)
    source : StartSource, how the pose was found (:data:`StartSource`)
    confident : bool, False when the start is uncertain (a search whose winner has a limb
        lost, or whose runner-up ranks within the least margin): its frame is flagged
        ``lost``
    label : str, the search's winning candidate (a pose library trial and frame
        ``"SS_TT:frame"`` or a seed pose's name, with its heading ``"@deg°"``); empty
        for the other sources
    score : float or None, the winner's fit score, metres (search only)
    key : float or None, the winner's ranking key, metres (search only)
    runner_up : str or None, the best candidate in a distinct pose (its label; None when
        the search found none, and for the other sources)
    runner_up_key : float or None, the runner-up's ranking key, metres
    lost : tuple of str, the winner's limbs the fit-quality check finds lost
    silhouette_cost : float or None, m²: the objective left by this pose's fit to the
        frame's silhouettes with the body held, where the start was chosen by it among
        candidates (:mod:`~meshmocap.estimate.performer.first_frame`); None otherwise
    rival_cost : float or None, m²: the same for the best candidate not chosen (None
        without one)
    """

    frame: int
    R: np.ndarray
    root: np.ndarray
    source: StartSource
    confident: bool = True
    label: str = ""
    score: float | None = None
    key: float | None = None
    runner_up: str | None = None
    runner_up_key: float | None = None
    lost: tuple[str, ...] = ()
    silhouette_cost: float | None = None
    rival_cost: float | None = None

    def __post_init__(self) -> None:
        R, root = np.asarray(self.R), np.asarray(self.root)
        if self.source not in START_SOURCES:
            raise InputError(
                f"Start: source must be one of {list(START_SOURCES)}, found {self.source!r}"
            )
        if R.ndim != 3 or R.shape[1:] != (3, 3) or root.shape != (3,):
            raise InputError(
                f"Start: expected R (J, 3, 3) and root (3,), found {R.shape} and {root.shape}"
            )

    @property
    def margin(self) -> float | None:
        """How much worse the runner-up ranks than the winner (metres of ranking key), or
        None without a runner-up."""
        if self.runner_up_key is None or self.key is None:
            return None
        return float(self.runner_up_key - self.key)


def start_json(start: Start) -> dict:
    """``start`` as plain JSON values (arrays as nested lists); :func:`start_of_json`
    reads it back bit for bit."""
    return {
        "frame": int(start.frame),
        "source": start.source,
        "confident": bool(start.confident),
        "R": np.asarray(start.R, dtype=np.float64).tolist(),
        "root": np.asarray(start.root, dtype=np.float64).tolist(),
        "label": start.label,
        "score": _number(start.score),
        "key": _number(start.key),
        "runner_up": start.runner_up,
        "runner_up_key": _number(start.runner_up_key),
        "lost": list(start.lost),
        "silhouette_cost": _number(start.silhouette_cost),
        "rival_cost": _number(start.rival_cost),
    }


def start_of_json(record: object, where: str = "start") -> Start:
    """The :class:`Start` that :func:`start_json` wrote (``where`` names the file or entry
    in the error).

    Raises
    ------
    FormatError
        Not such a record: a missing key, a value of the wrong kind, non-finite numbers.
    """
    try:
        if not isinstance(record, dict):
            raise TypeError(f"expected an object, found {type(record).__name__}")
        R = np.array(record["R"], dtype=np.float64)
        root = np.array(record["root"], dtype=np.float64)
        if not (np.isfinite(R).all() and np.isfinite(root).all()):
            raise ValueError("non-finite pose")
        return Start(
            frame=int(record["frame"]),
            R=R,
            root=root,
            source=str(record["source"]),  # type: ignore[arg-type]
            confident=_bool(record["confident"]),
            label=str(record.get("label", "")),
            score=_optional_float(record.get("score")),
            key=_optional_float(record.get("key")),
            runner_up=None if record.get("runner_up") is None else str(record["runner_up"]),
            runner_up_key=_optional_float(record.get("runner_up_key")),
            lost=tuple(str(x) for x in record.get("lost", ())),
            silhouette_cost=_optional_float(record.get("silhouette_cost")),
            rival_cost=_optional_float(record.get("rival_cost")),
        )
    except (KeyError, TypeError, ValueError, InputError) as exc:
        raise FormatError(f"{where}: not a start record ({type(exc).__name__}: {exc})") from None


def _number(x: float | None) -> float | None:
    """A finite float for JSON, or None (JSON has no NaN)."""
    return None if x is None or not math.isfinite(x) else float(x)


def _optional_float(x: object) -> float | None:
    if x is None:
        return None
    v = float(x)  # type: ignore[arg-type]
    if not math.isfinite(v):
        raise ValueError(f"non-finite number {v}")
    return v


def _bool(x: object) -> bool:
    if not isinstance(x, bool):
        raise TypeError(f"expected true or false, found {x!r}")
    return x
