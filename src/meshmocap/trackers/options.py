"""How a capture is tracked, as one record: :class:`TrackOptions`.

The driver (:func:`~meshmocap.trackers.driver.track_sequence`), :func:`meshmocap.api.track`
and the commands that track (``meshmocap track``, ``batch``, ``demo``) share this record:
its fields are checked once, when it is made (one line naming the field, what it must be
and the value found), and each part reads the same fields. The tracker's own options
(``n_patches``, ``max_iter``, ...) belong to the tracker, not here.

Frames are chosen by their frame NUMBERS (``frames``: the numbers the capture's files
carry, as ``--frames`` on the command line), or explicitly by their POSITIONS in the
capture (``positions``: 0 for its first frame, wherever its numbering starts); the two
agree on a capture numbered from 0 without gaps. :meth:`TrackOptions.positions_in` turns
either into positions, checked against the capture.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal, get_args

import numpy as np

from meshmocap._validate import check_choice, check_type, frame_positions
from meshmocap.body.light import LIGHT_VERTICES
from meshmocap.errors import InputError
from meshmocap.io.live import LiveCapture
from meshmocap.io.start import Start

__all__ = ["Init", "Passes", "Refine", "TrackOptions"]

#: How the first frame's pose is found: from the capture alone, or from its ground truth.
Init = Literal["auto", "truth"]
#: When the output surface is refined towards the observations (:class:`TrackOptions`).
Refine = Literal["auto", "on", "arap", "off"]
#: The passes over a capture on disk (:class:`TrackOptions`): the forward pass, then the
#: two-way pass over its lost runs (:mod:`meshmocap.trackers.two_way`); or the forward alone.
Passes = Literal["two-way", "forward"]

#: The name the record's errors speak under (the user's call: ``meshmocap.track``).
_OWNER = "track"


@dataclass(frozen=True, eq=False)
class TrackOptions:
    """How the driver tracks a capture (module docstring).

    Parameters
    ----------
    frames : slice or sequence of int, optional
        The frame NUMBERS to track, in the order given (default: all). A slice selects the
        numbers in its range that the capture has (``slice(3, 9)`` is frames 3 to 8
        wherever the capture starts, as ``--frames 3:9``); each number of a sequence must
        be one of the capture's.
    positions : slice or sequence of int, optional
        The frames to track by their positions in the capture (0 is its first frame), in
        the order given; instead of ``frames``, not with it.
    resume : bool
        Continue an interrupted run in the track folder (same settings) instead of
        starting over.
    show_progress : bool, optional
        Progress lines while tracking (default: where the output is not a terminal,
        every few seconds).
    vertices : bool
        Read the tracked vertices back into the returned track (False for long runs: see
        :func:`~meshmocap.io.results.read_track`).
    init : {"auto", "truth"}
        The first frame's pose: found from the frame alone (a global search over heading,
        place and the bundled pose library,
        :func:`~meshmocap.estimate.pose.first_pose.initial_pose`), or copied from its
        ground truth (the papers' protocol; the capture must have it). ``track.json``
        records which, and how the first pose was found (its ``start``).
    recover : bool
        Score every frame and flag a frame with a limb lost ``lost``
        (:class:`~meshmocap.estimate.recovery.reinit.Recovery`).
    refine : {"auto", "on", "arap", "off"}
        Refine each frame's output surface towards that frame's observations (what the
        skeleton's skin cannot follow: clothing, a rig that does not bend as the body
        does): ``"on"`` along its normals
        (:class:`~meshmocap.geometry.refine.SurfaceRefiner`), ``"arap"`` as rigidly as
        possible, each neighbourhood keeping its shape in the frame before's refined
        surface and each frame starting where the last one's refinement left the vertices
        with respect to the skin (:class:`~meshmocap.geometry.refine.ArapRefiner`:
        vertices keep their place on the body instead of sliding along it). Either way the
        joints and the tracker's state stay the skeleton's; on mesh or point-cloud files
        the skeleton is held with the frame before's ``"arap"`` surface
        (:mod:`meshmocap.estimate.pose.hold`). ``"auto"``: ``"arap"`` for mesh or
        point-cloud files (a 4D capture: their surface is the performer's), off for a
        capture folder carved from its cameras (a visual hull is larger than the body,
        and the surface would swell into it). ``track.json`` records it
        (``refine_surface``: false, true for ``"on"``, ``"arap"``).
    light : int or None
        Track a light copy of the template with about this many vertices
        (:mod:`meshmocap.body.light`; a template that is light already is tracked as it
        is): the frames hold its vertices, and :func:`~meshmocap.io.results.read_track`
        reads the template's out of them. None tracks the template itself.
    init_options : dict, optional
        Options of the automatic first pose's search
        (:func:`~meshmocap.estimate.pose.first_pose.initial_pose`, e.g. ``exclude_trials``).
    template_info : dict, optional
        How the template was chosen, kept in ``track.json`` (``template_source``:
        ``"given"``, ``"capture"`` or ``"estimated"``; ``template_file``); see
        :func:`meshmocap.estimate.performer.tracking_template.tracking_template`.
    start : Start, optional
        The pose of its frame (:attr:`~meshmocap.io.start.Start.frame`) when it is already
        known (a template made from that very frame): with ``init="auto"``, the track
        starts there without a search.
    passes : {"two-way", "forward"}
        After the forward pass, the two-way pass over the runs of frames it flagged
        ``lost`` (:mod:`meshmocap.trackers.two_way`: whole-body searches at keyframes,
        tracked backward and forward from them, per frame the hypothesis the evidence
        prefers), or the forward pass alone. The two-way pass needs ``recover`` and a
        capture on disk: a live capture is tracked forward only. ``track.json`` records
        which (``passes``) and what the two-way pass changed (``two_way``).
    """

    frames: slice | Sequence[int] | None = None
    positions: slice | Sequence[int] | None = None
    resume: bool = True
    show_progress: bool | None = None
    vertices: bool = True
    init: Init = "auto"
    recover: bool = True
    refine: Refine = "auto"
    light: int | None = LIGHT_VERTICES
    init_options: dict | None = None
    template_info: dict | None = None
    start: Start | None = None
    passes: Passes = "two-way"

    def __post_init__(self) -> None:
        for name in ("frames", "positions"):
            object.__setattr__(self, name, _selection(name, getattr(self, name)))
        if self.frames is not None and self.positions is not None:
            raise InputError(
                f"{_OWNER}: give frames (frame numbers) or positions (positions in the "
                "capture), not both"
            )
        for name in ("resume", "vertices", "recover"):
            check_type(_OWNER, name, getattr(self, name), bool, "True or False")
        if self.show_progress is not None:
            check_type(_OWNER, "show_progress", self.show_progress, bool, "True or False")
        check_choice(_OWNER, "init", self.init, get_args(Init))
        check_choice(_OWNER, "refine", self.refine, get_args(Refine))
        check_choice(_OWNER, "passes", self.passes, get_args(Passes))
        if self.light is not None:
            check_type(_OWNER, "light", self.light, (int, np.integer), "a vertex count or None")
            if self.light < 1:
                raise InputError(f"{_OWNER}: light must be ≥ 1 or None, found {self.light}")
        for name in ("init_options", "template_info"):
            if getattr(self, name) is not None:
                check_type(_OWNER, name, getattr(self, name), dict, "a dict or None")
        if self.start is not None:
            check_type(_OWNER, "start", self.start, Start, "a Start or None")

    def positions_in(self, capture) -> list[int] | None:
        """The positions in ``capture`` (its ``indices``: frame numbers, in order) of the
        frames to track, in the order given, or None for all of them.

        Raises
        ------
        InputError
            One line: a frame number the capture lacks or a position outside it (saying
            which it was, and the valid range), a selection with no frame, or any
            selection of a live capture (tracked whole, as its frames come).
        """
        if self.frames is None and self.positions is None:
            return None
        if isinstance(capture, LiveCapture):
            raise InputError(
                f"{_OWNER}: a live capture is tracked whole, as its frames come; no frames"
            )
        numbers = [int(i) for i in capture.indices]
        n = len(numbers)
        if self.positions is not None:
            if isinstance(self.positions, slice):
                out = list(range(n)[self.positions])
            else:
                out = list(self.positions)
                for k, v in enumerate(out):
                    if not 0 <= v < n:
                        raise InputError(
                            f"{_OWNER}: positions[{k}] must be a position in the capture, from "
                            f"0 to {n - 1}, found {v}"
                        )
        elif isinstance(self.frames, slice):
            out = frame_positions(numbers, self.frames)
        else:
            where = {v: k for k, v in enumerate(numbers)}
            out = []
            for k, v in enumerate(self.frames):
                if v not in where:
                    gaps = "" if numbers[-1] - numbers[0] + 1 == n else ", with gaps"
                    raise InputError(
                        f"{_OWNER}: frames[{k}] must be a frame number of the capture, "
                        f"{numbers[0]} to {numbers[-1]}{gaps}, found {v} "
                        "(positions= takes positions)"
                    )
                out.append(where[v])
        if not out:
            which = "frames" if self.positions is None else "positions"
            raise InputError(
                f"{_OWNER}: {which} selects none of the {n} frames of the capture (frame "
                f"numbers {numbers[0]} to {numbers[-1]}, positions 0 to {n - 1})"
            )
        return out


def _selection(name: str, value: object) -> slice | tuple[int, ...] | None:
    """``frames`` or ``positions`` checked: None, a slice, or a sequence of int (kept as a
    tuple)."""
    if value is None or isinstance(value, slice):
        return value
    if isinstance(value, str | bytes) or not isinstance(value, Sequence | np.ndarray):
        check_type(_OWNER, name, value, slice, "a slice or a sequence of int")
    out = tuple(value)
    what = "a frame number (int)" if name == "frames" else "a frame position (int)"
    for k, v in enumerate(out):
        check_type(_OWNER, f"{name}[{k}]", v, (int, np.integer), what)
    return tuple(int(v) for v in out)
