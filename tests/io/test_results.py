"""Track folders: frame flags written, read back and checked; older frame files still read."""

import numpy as np
import pytest

from meshmocap.errors import InputError
from meshmocap.io.results import FrameResult, frame_path, read_track, start_track, write_frame
from meshmocap.trackers.driver import read_track_frame


def _result(index, **kw):
    rng = np.random.default_rng(index)
    return FrameResult(index, rng.normal(size=(15, 3)), rng.normal(size=(4, 3)), **kw)


def test_flags_round_trip_through_frames_and_tracks(tmp_path):
    start_track(tmp_path, {"method": "test"}, np.array([[0, 1, 2], [0, 2, 3]]))
    write_frame(tmp_path, _result(0))
    write_frame(tmp_path, _result(1, healthy=False, flags=("missing",), message="no hull"))
    write_frame(tmp_path, _result(2, flags=("lost", "reinit"), message="lost: left arm"))
    track = read_track(tmp_path)
    assert track.flags == ((), ("missing",), ("lost", "reinit"))
    assert track.messages == ("", "no hull", "lost: left arm")
    assert track.healthy.tolist() == [True, False, True]
    assert read_track_frame(tmp_path, 2).flags == ("lost", "reinit")


def test_frame_files_without_flags_read_as_failed_when_unhealthy(tmp_path):
    """A frame file of a track written before flags existed."""
    start_track(tmp_path, {"method": "test"}, np.array([[0, 1, 2]]))
    for index, healthy in ((0, True), (1, False)):
        r = _result(index)
        np.savez_compressed(
            frame_path(tmp_path, index),
            index=index,
            joints=r.joints,
            vertices=r.vertices.astype(np.float32),
            n_iter=0,
            seconds=0.0,
            healthy=healthy,
            message=np.str_(""),
        )
    assert read_track(tmp_path).flags == ((), ("failed",))


def test_unknown_flag_is_rejected_naming_the_valid_ones():
    with pytest.raises(InputError, match=r"flags must be among \('failed', 'missing'.*'lsot'"):
        _result(0, flags=("lsot",))
