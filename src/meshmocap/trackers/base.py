"""What every tracker provides, and how a tracking run starts.

A tracker is a small stateful object: ``setup`` prepares it for a template, ``init`` places
the template on the first frame (from a known or estimated pose), ``step`` fits the next
frame and returns a :class:`~meshmocap.io.results.FrameResult`, and ``reseat``
re-initialises it mid-track at a pose found from the current frame (loss recovery,
:mod:`meshmocap.estimate.recovery.reinit`). The state it needs to continue is returned with each
result (``FrameResult.state``) and restored by ``set_state``, so the sequence driver can
resume an interrupted run and recover from a failed frame.
"""

from __future__ import annotations

from typing import Protocol

import numpy as np

from meshmocap.body.template import Template
from meshmocap.io.capture import CaptureFrame
from meshmocap.io.results import FrameResult


class Tracker(Protocol):
    """The interface of the trackers (``cage``, ``patch``, baselines)."""

    #: Short method name written in ``track.json``.
    name: str
    #: The template the tracker is set up for (None before :meth:`setup` or :meth:`init`).
    template: Template | None

    def setup(self, template: Template) -> None:
        """Precompute what tracking ``template`` needs (rig, model points, solvers) without
        placing it on a frame: a resumed run calls this, then :meth:`set_state`."""
        ...

    def init(
        self, template: Template, frame: CaptureFrame, R: np.ndarray, root: np.ndarray
    ) -> FrameResult:
        """Start on ``frame`` with the template posed by local rotations ``R`` (J, 3, 3) and
        root position ``root`` (3,) (e.g. the first frame's ground truth)."""
        ...

    def reseat(self, frame: CaptureFrame, R: np.ndarray, root: np.ndarray) -> FrameResult:
        """Re-initialise on ``frame`` (after a lost frame) with the template posed by
        ``R`` (J, 3, 3), ``root`` (3,), keeping what the first frame fixed (the joints'
        binding or coordinates, the data term's vertices) and forgetting the motion so far
        (no velocity is carried into the next frame). Returns the re-seated result."""
        ...

    def step(self, frame: CaptureFrame) -> FrameResult:
        """Fit the next frame, warm-started from the current state."""
        ...

    def set_state(self, state: dict[str, np.ndarray]) -> None:
        """Restore a state returned in an earlier :class:`FrameResult`."""
        ...

    def options(self) -> dict:
        """JSON-ready settings (written to ``track.json``; a resumed run must match)."""
        ...
