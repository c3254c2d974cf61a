"""The tracking record (meshmocap.trackers.options): checked once, in one line; ``frames``
are frame numbers everywhere and ``positions`` positions, each refused out of range saying
which it was and the valid range."""

from dataclasses import FrozenInstanceError
from types import SimpleNamespace

import numpy as np
import pytest

import meshmocap
from meshmocap.errors import ArgumentTypeError, InputError
from meshmocap.trackers.options import TrackOptions

#: A capture whose frame numbers start at 100 and skip 103 (positions 0 to 3).
NUMBERED = SimpleNamespace(indices=[100, 101, 102, 104], path="cap")


def test_frames_are_numbers_and_positions_positions_in_the_order_given():
    assert TrackOptions().positions_in(NUMBERED) is None  # every frame
    assert TrackOptions(frames=[104, 100]).positions_in(NUMBERED) == [3, 0]
    assert TrackOptions(frames=range(102, 99, -1)).positions_in(NUMBERED) == [2, 1, 0]
    assert TrackOptions(frames=slice(101, 104)).positions_in(NUMBERED) == [1, 2]  # as --frames
    assert TrackOptions(positions=[3, 0]).positions_in(NUMBERED) == [3, 0]
    assert TrackOptions(positions=slice(None, None, -1)).positions_in(NUMBERED) == [3, 2, 1, 0]
    assert TrackOptions(frames=np.array([101])).frames == (101,)  # kept as a tuple of int


@pytest.mark.parametrize(
    ("options", "said"),
    [
        (
            TrackOptions(frames=[100, 3]),
            "track: frames[1] must be a frame number of the capture, 100 to 104, with gaps, "
            "found 3 (positions= takes positions)",
        ),
        (
            TrackOptions(frames=[103]),
            "track: frames[0] must be a frame number of the capture, 100 to 104, with gaps, "
            "found 103",
        ),
        (
            TrackOptions(positions=[0, 4]),
            "track: positions[1] must be a position in the capture, from 0 to 3, found 4",
        ),
        (
            TrackOptions(positions=[-1]),
            "track: positions[0] must be a position in the capture, from 0 to 3, found -1",
        ),
        (
            TrackOptions(frames=slice(0, 100)),
            "track: frames selects none of the 4 frames of the capture (frame numbers 100 to "
            "104, positions 0 to 3)",
        ),
        (TrackOptions(positions=[]), "track: positions selects none of the 4 frames"),
    ],
)
def test_a_frame_outside_the_capture_is_refused_saying_which_it_was(options, said):
    with pytest.raises(InputError) as info:
        options.positions_in(NUMBERED)
    assert str(info.value).startswith(said) and "\n" not in str(info.value)


def test_the_record_is_checked_once_when_made_in_one_line():
    with pytest.raises(InputError, match=r"track: init must be one of \['auto', 'truth'\]"):
        TrackOptions(init="gt")
    with pytest.raises(
        InputError, match=r"track: refine must be one of \['auto', 'on', 'arap', 'off'\]"
    ):
        TrackOptions(refine="yes")
    with pytest.raises(InputError, match=r"give frames \(frame numbers\) or positions"):
        TrackOptions(frames=[1], positions=[1])
    with pytest.raises(InputError, match="light must be ≥ 1 or None, found 0"):
        TrackOptions(light=0)
    for kw, said in [
        ({"resume": "no"}, "track: resume must be True or False, found str 'no'"),
        ({"recover": 1}, "track: recover must be True or False, found int 1"),
        ({"frames": "0:3"}, "track: frames must be a slice or a sequence of int, found str"),
        ({"frames": [1, 2.0]}, "track: frames[1] must be a frame number (int), found float"),
        ({"positions": [None]}, "track: positions[0] must be a frame position (int), found"),
        ({"init_options": ["x"]}, "track: init_options must be a dict or None, found list"),
        ({"start": 3}, "track: start must be a Start or None, found int 3"),
    ]:
        with pytest.raises(ArgumentTypeError) as info:
            TrackOptions(**kw)
        assert str(info.value).startswith(said), str(info.value)
    with pytest.raises(FrozenInstanceError):
        TrackOptions().resume = False  # type: ignore[misc]


def test_track_builds_the_record_from_its_keywords_and_takes_one_whole():
    from meshmocap.api import track_options

    assert track_options(frames=[1], init="truth").init == "truth"
    given = TrackOptions(positions=[0, 1], recover=False, resume=False)
    same = track_options(given, resume=True, init="auto", show_progress=None)
    assert same is given  # keywords left at their defaults keep the record's fields
    changed = track_options(given, init="truth", vertices=False)
    assert (changed.init, changed.vertices, changed.recover, changed.positions) == (
        "truth",
        False,
        False,
        (0, 1),
    )
    with pytest.raises(InputError, match="not both"):
        track_options(given, frames=[3])
    with pytest.raises(ArgumentTypeError, match="track: options must be a TrackOptions"):
        meshmocap.track("c", options={"init": "truth"})
    with pytest.raises(ArgumentTypeError, match="track: frames must be a slice or a sequence"):
        meshmocap.track("c", frames=3)
    assert meshmocap.TrackOptions is TrackOptions
