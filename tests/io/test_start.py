"""The start record as plain JSON values: read back bit for bit, refused in one line when
it is not one."""

import json

import numpy as np
import pytest

from meshmocap.errors import FormatError, InputError
from meshmocap.io.start import Start, start_json, start_of_json


def _start(**kw):
    rng = np.random.default_rng(3)
    R = rng.normal(size=(31, 3, 3))
    R[0, 0, 0] = -0.0  # a signed zero, and values with every bit of their mantissa
    fields = dict(
        frame=7,
        R=R,
        root=rng.normal(size=3),
        source="search",
        confident=False,
        label="13_32:40@135°",
        score=0.0345678901234,
        key=0.04681,
        runner_up="07_05:11@0°",
        runner_up_key=0.0469,
        lost=("left_arm",),
        silhouette_cost=3.1415e-5,
        rival_cost=4.2e-5,
    )
    return Start(**{**fields, **kw})


def test_a_start_reads_back_bit_for_bit_through_json_text():
    s = _start()
    back = start_of_json(json.loads(json.dumps(start_json(s))))
    assert back.R.dtype == back.root.dtype == np.float64
    assert back.R.tobytes() == s.R.tobytes() and back.root.tobytes() == s.root.tobytes()
    names = ("frame", "source", "confident", "label", "score", "key", "runner_up", "lost")
    for name in (*names, "silhouette_cost", "rival_cost"):
        assert getattr(back, name) == getattr(s, name)
    assert back.margin == s.margin == pytest.approx(0.00009, abs=1e-12)
    # the other sources carry no search: no numbers, no runner-up, no margin
    truth = start_of_json(json.loads(json.dumps(start_json(_start(source="truth", **_bare())))))
    assert truth.score is None and truth.runner_up is None and truth.margin is None
    assert truth.silhouette_cost is None and truth.rival_cost is None
    assert truth.confident


def _bare():
    return dict(
        confident=True,
        label="",
        score=None,
        key=None,
        runner_up=None,
        runner_up_key=None,
        lost=(),
        silhouette_cost=None,
        rival_cost=None,
    )


def test_what_is_not_a_start_is_refused_in_one_line():
    good = start_json(_start())
    for bad in (
        [],
        {k: v for k, v in good.items() if k != "R"},
        {**good, "R": [[1.0, 2.0]]},
        {**good, "root": [0.0, float("nan"), 0.0]},
        {**good, "source": "guess"},
        {**good, "confident": "yes"},
        {**good, "score": "high"},
    ):
        with pytest.raises(FormatError, match=r"^T/track.json: 'start': not a start record") as e:
            start_of_json(bad, "T/track.json: 'start'")
        assert "\n" not in str(e.value)
    with pytest.raises(InputError, match=r"source must be one of \['search', 'truth'"):
        _start(source="guess")
