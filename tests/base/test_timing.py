"""The stage timer: per-frame seconds per stage, their medians and the one-line summary."""

import pytest

from meshmocap._timing import FRAME_STAGES, StageTimer, touched


def _timer(frames):
    t = StageTimer()
    for rec in frames:
        t.start()
        for stage, seconds in rec.items():
            t.add(stage, seconds)
    return t


def test_medians_and_total_skip_the_first_frame():
    t = _timer(
        [
            {"read": 1.0, "step": 9.0},  # frame 1: compiling
            {"read": 0.002, "step": 0.100, "step.solve": 0.060, "write": 0.004},
            {"read": 0.004, "step": 0.120, "step.solve": 0.070, "write": 0.006},
            {"read": 0.003, "step": 0.110, "step.solve": 0.065, "write": 0.005},
        ]
    )
    m = t.medians(skip=1)
    assert m["read"] == pytest.approx(0.003)
    assert m["step"] == pytest.approx(0.110)
    assert m["step.solve"] == pytest.approx(0.065)
    # the total adds the driver's stages, not the tracker's parts of the step
    assert m["total"] == pytest.approx(0.003 + 0.110 + 0.005)
    assert t.stages() == ["read", "step", "step.solve", "write"]
    line = t.summary()
    assert line == (
        "per frame (median of 3): read 3.0 ms, step 110 ms (solve 65), write 5.0 ms; 118 ms in all"
    )


def test_laps_book_wall_and_cpu_time_to_the_stage_that_ends():
    t = StageTimer()
    t.start()
    sum(i * i for i in range(200_000))  # some CPU work
    t.lap("step")
    t.lap("write")
    assert set(t.frames[0]) == set(t.cpu[0]) == {"step", "write"}
    assert t.frames[0]["step"] > t.frames[0]["write"] >= 0
    assert t.cpu[0]["step"] > 0
    assert t.medians(cpu=True)["step"] == t.cpu[0]["step"]
    assert set(FRAME_STAGES) >= set(t.stages())


def test_no_frame_no_summary_and_touched_names_computed_properties():
    assert StageTimer().summary() == "" and StageTimer().medians() == {}

    class Lazy:
        def __init__(self):
            self.points = 1

    assert touched(Lazy(), ("hull", "points")) == ("points",)
    assert touched(object(), ("hull",)) == ()
