"""Where a tracked frame's time goes: seconds per stage, recorded by the tracking driver
when it is handed a :class:`StageTimer` (``track_sequence(..., timer=StageTimer())``,
``meshmocap track`` prints its :meth:`StageTimer.summary`). Without one the driver records
nothing (no clock is read).

The stages of a frame, in the order the driver runs them (:data:`FRAME_STAGES`):

* ``read``: the frame's files as the driver reads them (a capture folder's hull mesh or
  occupancy, a mesh sequence's file);
* ``observe``: what is derived from them once for the tracker and the checks (surface
  points and normals, the signed distance's set-up);
* ``step``: the tracker's fit, with its own stages (``step.NAME``, the tracker's
  ``stage_seconds``) where it keeps them;
* ``hold``: on a 4D capture, the pose fitted against the observations with the tracker's
  surface, the tracker moved there (:mod:`meshmocap.estimate.pose.hold`);
* ``checks``: the fit-quality assessment of every frame, and any re-seat;
* ``refine``: the output surface refined towards the frame's observations
  (:class:`~meshmocap.geometry.refine.SurfaceRefiner`);
* ``write``: the frame's result file.
"""

from __future__ import annotations

import time
from collections.abc import Iterable

import numpy as np

#: The driver's stages of a frame, in order (module docstring).
FRAME_STAGES = ("read", "observe", "step", "hold", "checks", "refine", "write")


class StageTimer:
    """Seconds per stage of each frame tracked (not the first, which is placed rather than
    tracked).

    Attributes
    ----------
    frames : list of dict of str → float
        One dict per frame: wall seconds per stage (:data:`FRAME_STAGES`, and ``step.NAME``
        for the tracker's own stages, which add up to about ``step``).
    cpu : list of dict of str → float
        The same, CPU seconds of this process (what a stage costs when the machine is
        shared); the driver's stages only (the trackers clock their own in wall time).
    """

    def __init__(self) -> None:
        self.frames: list[dict[str, float]] = []
        self.cpu: list[dict[str, float]] = []
        #: Lazily computed attributes of the frame (``reads``) and of its observed wrapper
        #: (``derived``) the last frame used: the driver computes them up front on the next
        #: frame, so that their time is booked to ``read`` and ``observe``, not to the step
        #: that first asked for them (the same work, done earlier).
        self.reads: tuple[str, ...] = ()
        self.derived: tuple[str, ...] = ()
        self._t = self._c = 0.0

    def start(self) -> None:
        """Start a new frame's record; the clocks run from now."""
        self.frames.append({})
        self.cpu.append({})
        self._t, self._c = time.perf_counter(), time.process_time()

    def lap(self, stage: str) -> None:
        """Book the time since the last lap (or :meth:`start`) to ``stage``."""
        t, c = time.perf_counter(), time.process_time()
        self.add(stage, t - self._t)
        _book(self.cpu[-1], stage, c - self._c)
        self._t, self._c = t, c

    def add(self, stage: str, seconds: float) -> None:
        """Add ``seconds`` (wall) to ``stage`` of the current frame."""
        _book(self.frames[-1], stage, seconds)

    def stages(self, *, cpu: bool = False) -> list[str]:
        """Every stage recorded (in CPU time, with ``cpu``), the driver's in order, each
        followed by its parts."""
        seen = {k for f in (self.cpu if cpu else self.frames) for k in f}
        out = []
        for s in FRAME_STAGES:
            out += [s] * (s in seen) + sorted(k for k in seen if k.startswith(f"{s}."))
        return out + sorted(seen - set(out))

    def medians(self, *, skip: int = 0, cpu: bool = False) -> dict[str, float]:
        """The median seconds per frame of each stage (a frame without it counts 0) and
        of their sum (``"total"``), over the frames after the first ``skip``; ``cpu``: the
        CPU seconds (:attr:`cpu`) instead of wall."""
        records = self.cpu if cpu else self.frames
        frames = records[skip:] or records
        if not frames:
            return {}
        out = {s: float(np.median([f.get(s, 0.0) for f in frames])) for s in self.stages(cpu=cpu)}
        out["total"] = float(np.median([_total(f) for f in frames]))
        return out

    def summary(self, *, skip: int = 1) -> str:
        """One line: the median milliseconds per frame of each stage, e.g. ``"per frame
        (median of 39): read 4 ms, observe 2 ms, step 130 ms (observations 9, classify 12,
        ...), checks 80 ms, write 6 ms; 222 ms in all"`` (frames after the first ``skip``,
        whose time is mostly compiling and warming caches); ``""`` with no frame."""
        m = self.medians(skip=skip)
        if not m:
            return ""
        n = len(self.frames[skip:] or self.frames)
        parts = []
        for s in (s for s in self.stages() if "." not in s):
            sub = [k for k in m if k.startswith(f"{s}.")]
            inner = ", ".join(f"{k.split('.', 1)[1]} {_ms(m[k])}" for k in sub)
            parts.append(f"{s} {_ms(m[s])} ms" + (f" ({inner})" if inner else ""))
        return f"per frame (median of {n}): {', '.join(parts)}; {_ms(m['total'])} ms in all"


def _book(record: dict[str, float], stage: str, seconds: float) -> None:
    record[stage] = record.get(stage, 0.0) + float(seconds)


def _total(frame: dict[str, float]) -> float:
    return sum(v for k, v in frame.items() if "." not in k)


def _ms(seconds: float) -> str:
    ms = 1000 * seconds
    return f"{ms:.0f}" if ms >= 10 else f"{ms:.1f}"


def touched(obj: object, names: Iterable[str]) -> tuple[str, ...]:
    """Which of ``names`` (cached properties) ``obj`` has computed already."""
    have = getattr(obj, "__dict__", {})
    return tuple(n for n in names if n in have)
