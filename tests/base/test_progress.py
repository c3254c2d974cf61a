"""Honest progress: the time left comes from a moving rate that leaves out the first item
(compiling, setting up), and a long step without a bar says what it is doing."""

import time

import pytest

from meshmocap import _progress
from meshmocap._progress import RATE_WINDOW, phase, progress


class _Clock:
    """A clock the test advances by hand."""

    def __init__(self) -> None:
        self.now = 100.0

    def __call__(self) -> float:
        return self.now


def test_the_time_left_ignores_the_first_items_setup(monkeypatch, capsys):
    """40 frames: the first takes 25 s (compiling), the others 0.4 s. After frame 1 the
    log says it is estimating; after frame 2 it says about 15 s left (38 × 0.4), not the
    ~20 min the mean rate over frames 1–2 would give."""
    clock = _Clock()
    monkeypatch.setattr(_progress.time, "perf_counter", clock)
    monkeypatch.setenv("MESHMOCAP_PROGRESS_SECONDS", "0")
    lines = []
    for k in progress(range(40), label="icp"):
        clock.now += 25.0 if k == 0 else 0.4
        if k in (1, 2, 20):
            lines.append(capsys.readouterr().err.strip().splitlines()[-1])
    assert lines[0] == "icp: 1/40 (2 %), estimating the time left"
    assert lines[1] == "icp: 2/40 (5 %), 2.50 it/s, about 15 s left"
    assert lines[2].endswith("2.50 it/s, about 8 s left")  # 20 left at 0.4 s


def test_the_rate_moves_with_the_last_items(monkeypatch, capsys):
    clock = _Clock()
    monkeypatch.setattr(_progress.time, "perf_counter", clock)
    monkeypatch.setenv("MESHMOCAP_PROGRESS_SECONDS", "0")
    for k in progress(range(100), label="x"):
        clock.now += 1.0 if k < 50 else 0.1  # ten times faster after frame 50
        if k == 50 + RATE_WINDOW:
            last = capsys.readouterr().err.strip().splitlines()[-1]
    assert last.endswith("10.00 it/s, about 4 s left")  # 39 left at 0.1 s


def test_a_long_phase_says_what_it_is_doing_and_a_short_one_stays_quiet(monkeypatch, capsys):
    monkeypatch.setattr(_progress, "PHASE_SECONDS", 0.05)
    with phase("estimating the body"):
        time.sleep(0.5)
    err = capsys.readouterr().err.splitlines()
    assert err[0] == "meshmocap: estimating the body ..."
    assert err[1].startswith("meshmocap: estimating the body: done in ")
    with phase("finding the first pose"):
        pass
    with phase("quiet", enabled=False):
        time.sleep(0.2)
    assert capsys.readouterr().err == ""


def test_a_phase_that_fails_lets_the_error_through(monkeypatch, capsys):
    monkeypatch.setattr(_progress, "PHASE_SECONDS", 10.0)
    with pytest.raises(ValueError, match="bad"), phase("x"):
        raise ValueError("bad")
    assert capsys.readouterr().err == ""
