"""Track folders: frame flags and the start written, read back and checked; older frame files
and folders still read."""

import json

import numpy as np
import pytest

from meshmocap.errors import FormatError, InputError
from meshmocap.io.results import (
    FORMAT,
    TWO_WAY_FOLDER,
    FrameResult,
    frame_path,
    read_start,
    read_track,
    read_two_way,
    start_track,
    two_way_changes,
    write_frame,
    write_start,
    write_two_way,
)
from meshmocap.io.start import Start
from meshmocap.trackers.frame_step import read_track_frame


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


def test_the_start_is_recorded_in_track_json_and_read_back(tmp_path):
    rng = np.random.default_rng(2)
    s = Start(0, rng.normal(size=(31, 3, 3)), rng.normal(size=3), "search", False, "a@0°")
    meta, F = {"method": "test"}, np.array([[0, 1, 2]])
    start_track(tmp_path, meta, F)
    assert read_start(tmp_path) is None  # not started yet
    write_start(tmp_path, s)
    write_frame(tmp_path, _result(0, flags=("lost",)))
    for back in (read_start(tmp_path), read_track(tmp_path).start):
        assert back.R.tobytes() == s.R.tobytes() and back.root.tobytes() == s.root.tobytes()
        assert (back.frame, back.source, back.confident, back.label) == (0, "search", False, "a@0°")
    assert start_track(tmp_path, meta, F) == [0]  # resumed: the start found is kept
    assert read_start(tmp_path).label == "a@0°"
    with pytest.raises(FormatError, match="other settings"):
        start_track(tmp_path, {"method": "other"}, F)
    start_track(tmp_path, meta, F, resume=False)  # started over: no start yet
    assert read_start(tmp_path) is None


def test_a_track_folder_without_a_start_reads_with_the_start_unknown(tmp_path):
    """A track written before starts were recorded: its first frame's message is not read."""
    start_track(tmp_path, {"method": "test", "init": "auto"}, np.array([[0, 1, 2]]))
    write_frame(tmp_path, _result(0, message="init auto: 02_02:2@0°; uncertain start (x)"))
    assert read_start(tmp_path) is None and read_track(tmp_path).start is None
    assert read_track(tmp_path).flags == ((),)  # no flag made from the message
    meta = json.loads((tmp_path / "track.json").read_text())
    (tmp_path / "track.json").write_text(json.dumps({**meta, "start": {"frame": 0}}))
    with pytest.raises(FormatError, match=r"track.json: 'start': not a start record"):
        read_track(tmp_path)


def test_a_track_made_before_the_limb_only_reseat_was_removed_resumes(tmp_path):
    """``track.json`` of an older track says ``"reseat": false``: the same settings as a
    track made now, so it resumes (and is read); one made with the re-seat on does not."""
    meta, F = {"method": "test", "recover": True}, np.array([[0, 1, 2]])
    start_track(tmp_path / "off", {**meta, "reseat": False}, F)
    write_frame(tmp_path / "off", _result(0))
    assert read_track(tmp_path / "off").meta["reseat"] is False
    assert start_track(tmp_path / "off", meta, F) == [0]  # resumed as it was
    assert "reseat" not in json.loads((tmp_path / "off" / "track.json").read_text())
    start_track(tmp_path / "on", {**meta, "reseat": True}, F)
    with pytest.raises(FormatError, match="other settings"):
        start_track(tmp_path / "on", meta, F)


def test_a_track_made_before_the_settings_added_since_resumes_as_it_was_made(tmp_path):
    """A folder written before ``track.json`` recorded the passes, the skeleton hold, the
    surface refinement, the cage's body and the patch term scales (and under the cage's old
    option name) resumes where the run now has the values tracks were made with then; where
    it has another, it is refused naming the setting."""
    F = np.array([[0, 1, 2]])
    before = {
        "method": "test",
        "recover": True,
        "reseat": False,
        "options": {"lambda_rigid": 1.0, "local_damping": 3e-5},
    }
    now = {
        "method": "test",
        "recover": True,
        "passes": "two-way",
        "hold_skeleton": False,
        "refine_surface": False,
        "cage_body": "template",
        "options": {
            "lambda_rigid": 1.0,
            "anchor_weight": 3e-5,
            "rigidity_scale": 10.0,
            "bone_scale": 100.0,
        },
    }
    for name in ("old", "held", "scaled"):
        (tmp_path / name / "frames").mkdir(parents=True)
        (tmp_path / name / "track.json").write_text(json.dumps({"format": FORMAT, **before}))
        write_frame(tmp_path / name, _result(0))
    assert start_track(tmp_path / "old", now, F) == [0]  # resumed as it was made
    assert json.loads((tmp_path / "old" / "track.json").read_text())["hold_skeleton"] is False
    with pytest.raises(FormatError, match=r"\(hold_skeleton: false there, true now\)"):
        start_track(tmp_path / "held", {**now, "hold_skeleton": True}, F)
    paper = {**now["options"], "rigidity_scale": 1.0}
    with pytest.raises(FormatError, match=r"\(options.rigidity_scale: 10.0 there, 1.0 now\)"):
        start_track(tmp_path / "scaled", {**now, "options": paper}, F)
    assert start_track(tmp_path / "held", now, F) == [0]  # refused: left as it was


def test_the_two_way_record_and_passes_survive_a_resume_and_not_a_restart(tmp_path):
    """A forward track resumes with the two-way pass (``passes`` may change); the pass's
    record and folder are kept on a resume and cleared when the run starts over."""
    meta, F = {"method": "test", "passes": "forward"}, np.array([[0, 1, 2]])
    start_track(tmp_path, meta, F)
    write_frame(tmp_path, _result(0))
    record = {"changed": [{"frames": [3, 5], "keyframe": 6, "direction": "backward"}]}
    write_two_way(tmp_path, record)
    (tmp_path / TWO_WAY_FOLDER / "keys").mkdir(parents=True)
    assert start_track(tmp_path, {**meta, "passes": "two-way"}, F) == [0]
    assert read_two_way(tmp_path) == record
    assert set(two_way_changes(read_track(tmp_path).meta)) == {3, 4, 5}
    start_track(tmp_path, meta, F, resume=False)
    assert read_two_way(tmp_path) is None and not (tmp_path / TWO_WAY_FOLDER).exists()
    with pytest.raises(FormatError, match="two-way change"):
        two_way_changes({"two_way": {"changed": [{"frames": "x"}]}})
    # a limb grafted from another track joins its frames' notes
    graft = {"frames": [5, 7], "limb": "left_arm", "track": "forward"}
    notes = two_way_changes({"two_way": {**record, "grafted": [graft]}})
    assert set(notes) == {3, 4, 5, 6, 7}
    assert notes[5] == "keyframe 6, backward; left_arm from the forward track"
    with pytest.raises(FormatError, match="two-way graft"):
        two_way_changes({"two_way": {"grafted": [{"frames": [1, 2]}]}})
