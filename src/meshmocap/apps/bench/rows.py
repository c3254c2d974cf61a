"""Rows of ``meshmocap bench``: one result per (capture, method), and the points of the
patch tracker's kept-fraction sweep (Fig. 8). :mod:`meshmocap.apps.bench.report` writes
them; :mod:`meshmocap.apps.bench.plots` draws them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, fields
from pathlib import Path

import numpy as np

from meshmocap.analysis.evaluate import Evaluation

__all__ = ["BenchRow", "TradeoffPoint", "not_applicable", "row_from_evaluation"]

_NAN = math.nan


@dataclass(frozen=True, eq=False)
class BenchRow:
    """One (capture, method) result; numbers are NaN where not applicable.

    Attributes
    ----------
    capture, method : str
    status : ``"ok"`` or ``"n/a"``; note : why not applicable (empty when ok)
    metric : ``"joints"`` (mean over the evaluation joints) or ``"vertices"`` (per-vertex
        correspondence error, skeleton-less captures)
    frames : int, frames tracked
    mean_mm, median_mm, std_mm : float, over all (frame, joint or vertex) pairs, mm
    worst_frame_mm : float, largest per-frame mean error, mm
    silhouette_error : float, pixel overlap error (ratio, 0.05 = 5 %)
    bone_std_max_mm : float, largest standard deviation of a bone's length, mm
    seconds_per_frame : float, mean tracking time after the first frame, s
    flagged : int, frames the driver flagged unhealthy
    frame_numbers : (T,) int, frames of ``per_frame_mm``; per_frame_mm : (T,) float, mm
    bone_names : tuple of B str; bone_mean_mm, bone_std_mm : (B,) float, mm
    track : str, the track folder
    init : str, how the first pose was found, in words
        (:func:`~meshmocap.estimate.pose.start.start_description`)
    start : str, the start record's source (:attr:`~meshmocap.io.start.Start.source`:
        ``search``, ``truth``, ...; ``""`` where the track records none)
    lost : int, frames flagged ``lost`` (a limb or the body off the observations)
    template : str, the tracking template and how it was chosen (``io.results.template_label``)
    """

    capture: str
    method: str
    status: str = "ok"
    note: str = ""
    metric: str = ""
    frames: int = 0
    mean_mm: float = _NAN
    median_mm: float = _NAN
    std_mm: float = _NAN
    worst_frame_mm: float = _NAN
    silhouette_error: float = _NAN
    bone_std_max_mm: float = _NAN
    seconds_per_frame: float = _NAN
    flagged: int = 0
    frame_numbers: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    per_frame_mm: np.ndarray = field(default_factory=lambda: np.zeros(0))
    bone_names: tuple[str, ...] = ()
    bone_mean_mm: np.ndarray = field(default_factory=lambda: np.zeros(0))
    bone_std_mm: np.ndarray = field(default_factory=lambda: np.zeros(0))
    track: str = ""
    init: str = ""
    start: str = ""
    lost: int = 0
    template: str = ""

    def to_json(self) -> dict:
        """JSON-ready fields (NaN as None)."""
        d = {}
        for f in fields(self):
            v = getattr(self, f.name)
            if isinstance(v, np.ndarray | tuple):
                v = v.tolist() if isinstance(v, np.ndarray) else list(v)
            d[f.name] = None if isinstance(v, float) and math.isnan(v) else v
        return d

    @classmethod
    def from_json(cls, d: dict, **override: str) -> BenchRow:
        """Inverse of :meth:`to_json`; ``override`` replaces fields (e.g. ``method``)."""
        d = {**d, **override}
        for k in ("frame_numbers", "per_frame_mm", "bone_mean_mm", "bone_std_mm"):
            d[k] = np.asarray(d[k], dtype=np.int64 if k == "frame_numbers" else np.float64)
        d["bone_names"] = tuple(d["bone_names"])
        floats = [f.name for f in fields(cls) if f.type == "float"]
        return cls(**{k: (_NAN if k in floats and v is None else v) for k, v in d.items()})


@dataclass(frozen=True, eq=False)
class TradeoffPoint:
    """One point of Fig. 8: the patch tracker with a kept fraction ``keep_fraction``."""

    keep_fraction: float
    row: BenchRow


def not_applicable(capture: str, method: str, why: str) -> BenchRow:
    """A row for a method that cannot run on a capture (no numbers are made up)."""
    return BenchRow(capture, method, status="n/a", note=why)


def row_from_evaluation(capture: str, method: str, ev: Evaluation, *, track: Path) -> BenchRow:
    """Summarise an evaluation: joint errors where the capture has joints, else the
    per-vertex correspondence error."""
    errs, metric = (ev.joints, "joints") if ev.joints is not None else (ev.correspondence, "")
    metric = metric or ("vertices" if errs is not None else "")
    if errs is None:
        return not_applicable(capture, method, "the capture has no ground truth")
    o, per_frame = errs.overall, errs.per_frame
    bones = ev.bones if ev.bones is not None and ev.bones.lengths.size else None
    return BenchRow(
        capture,
        method,
        metric=metric,
        frames=ev.n_frames,
        mean_mm=o.mean,
        median_mm=o.median,
        std_mm=o.std,
        worst_frame_mm=float(per_frame.max()) if per_frame.size else _NAN,
        silhouette_error=ev.silhouettes.overall if ev.silhouettes is not None else _NAN,
        bone_std_max_mm=float(bones.std.max()) if bones is not None else _NAN,
        seconds_per_frame=ev.seconds.mean,
        flagged=ev.unhealthy,
        frame_numbers=np.asarray(errs.frames, dtype=np.int64),
        per_frame_mm=per_frame,
        bone_names=bones.names if bones is not None else (),
        bone_mean_mm=bones.mean if bones is not None else np.zeros(0),
        bone_std_mm=bones.std if bones is not None else np.zeros(0),
        track=str(track),
        init=ev.init,
        start=ev.start.source if ev.start is not None else "",
        lost=ev.lost,
        template=ev.template,
    )
