"""One frame tracked: a frame that cannot be fitted or read is flagged and coasted across
from the last good frame; the driver's own tests track whole sequences through it."""

import numpy as np

from meshmocap.errors import FitError
from meshmocap.io.results import FrameResult, start_track, write_frame
from meshmocap.trackers.frame_step import (
    failure_reason,
    is_finite_result,
    missing_reason,
    read_track_frame,
    track_frame,
)


class _Failing:
    """A tracker whose step fails; it remembers the state it is reset to."""

    name = "failing"
    template = None

    def step(self, frame):
        raise FitError("no convergence\nsecond line")

    def set_state(self, state):
        self.state = state


def test_a_failed_frame_repeats_the_last_good_one_flagged(tmp_path):
    start_track(tmp_path, {"method": "failing"}, np.zeros((1, 3), int), resume=False)
    good = FrameResult(3, np.ones((15, 3)), np.ones((4, 3)), state={"x": np.arange(2)})
    write_frame(tmp_path, good)
    tracker = _Failing()
    frame = type("Frame", (), {"index": 4})()
    r = track_frame(tracker, lambda: frame, 4, tmp_path, 3)
    assert r.index == 4 and not r.healthy and r.flags == ("failed",)
    assert r.message == "FitError: no convergence"
    assert np.array_equal(r.joints, good.joints) and tracker.state["x"].tolist() == [0, 1]
    # a frame that cannot be read is missing, and coasted across the same way
    r = track_frame(tracker, _absent, 5, tmp_path, 3)
    assert r.flags == ("missing",) and "absent" in r.message
    assert read_track_frame(tmp_path, 3).index == 3


def _absent():
    from meshmocap.errors import MeshmocapFileNotFoundError

    raise MeshmocapFileNotFoundError("hull 00005.ply absent")


def test_reasons_and_finiteness():
    assert failure_reason(ValueError("x" * 300)).startswith("ValueError: x")
    assert len(failure_reason(ValueError("x" * 300))) == 200
    assert missing_reason(object()) is None
    assert missing_reason(type("F", (), {"missing": "dropped"})()) == "dropped"
    bad = FrameResult(0, np.full((15, 3), np.nan), np.zeros((4, 3)))
    assert not is_finite_result(bad)
