"""A start is decided once, from the search's result, and its frame's flags and message
are made from the record."""

import numpy as np
import pytest

from meshmocap.estimate.pose.first_pose import InitResult
from meshmocap.estimate.pose.fit import PoseFit
from meshmocap.estimate.pose.start import (
    START_MARGIN,
    search_start,
    start_description,
    start_flags,
    start_message,
)
from meshmocap.io.start import Start

R = np.tile(np.eye(3), (31, 1, 1))
ROOT = np.array([0.1, 0.2, 0.95])


def _result(margin=None, lost=()):
    """A search's result: winner key 46.8 mm, fit score 34.5 mm, a runner-up ``margin``
    metres behind (None: no runner-up)."""
    ru = None if margin is None else PoseFit(R, ROOT, 0.05, "07_05:11@0°")
    ru_key = float("inf") if margin is None else 0.0468 + margin
    return InitResult(
        R, ROOT, 0.0345, "02_02:2@0°", (), 0.0468, ru, ru_key, float("nan"), tuple(lost)
    )


def test_a_start_is_uncertain_with_a_limb_lost_or_a_close_runner_up():
    sure = search_start(4, _result(margin=0.0366))
    assert sure.confident and sure.frame == 4 and start_flags(sure) == ()
    assert sure.R is R and sure.root is ROOT  # the search's very arrays
    assert sure.runner_up == "07_05:11@0°" and sure.margin == pytest.approx(0.0366, abs=1e-15)
    assert search_start(0, _result()).confident  # no distinct runner-up: nothing close
    close = search_start(0, _result(margin=0.5 * START_MARGIN))
    lost = search_start(0, _result(margin=0.0366, lost=("left_arm",)))
    for s in (close, lost):
        assert not s.confident and start_flags(s) == ("lost",)


def test_the_message_is_made_from_the_record():
    assert start_message(search_start(0, _result(margin=0.0366))) == (
        "init auto: 02_02:2@0°, fit score 34.5 mm, key 46.8; runner-up 07_05:11@0° (+36.6 mm)"
    )
    assert start_message(search_start(0, _result(margin=0.001, lost=("left_arm",)))) == (
        "init auto: 02_02:2@0°, fit score 34.5 mm, key 46.8; runner-up 07_05:11@0° (+1.0 mm); "
        "uncertain start (left_arm lost, runner-up within 2 mm)"
    )
    said = {
        "truth": "init truth: the first pose from ground truth",
        "rest": "init truth: the template is this frame, in its rest pose",
        "subject-rest": "init template: the template was made from frame 3, in its rest pose",
        "subject-fit": "init template: the template was made from frame 3, in the pose fitted "
        "with the body",
    }
    for source, text in said.items():
        assert start_message(Start(3, R, ROOT, source)) == text
    assert start_description(None) == "unknown"
