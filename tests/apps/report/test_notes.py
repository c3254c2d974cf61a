"""What the report says beside its numbers: why frames were skipped or flagged, why the
silhouette column is n/a, what "worst frame" is, why a bone's spread is 0.0."""

from dataclasses import replace

import numpy as np
import pytest

from meshmocap.analysis.evaluate import evaluate
from meshmocap.apps.report.notes import frame_ranges, frame_rows
from meshmocap.apps.report.page import comparison_table, evaluation_tables, table_html
from meshmocap.body.template import EVAL_NAMES, EVAL_PARENTS
from meshmocap.io.results import FrameResult, read_track, start_track, write_frame


@pytest.fixture(scope="module")
def scored(synth_capture, tmp_path_factory):
    """A 4-frame capture and a track of its truth with flagged frames, evaluated."""
    root = tmp_path_factory.mktemp("notes")
    cap = synth_capture("walk", stop=4)
    meta = {
        "method": "patch",
        "template": "neutral_5k",
        "eval_names": list(EVAL_NAMES),
        "eval_parents": EVAL_PARENTS.tolist(),
    }
    start_track(root / "t", meta, cap.truth_faces, resume=False)
    flags = {1: (("lost",), "left arm below the quality threshold"), 2: (("missing",), "")}
    for f in cap:
        fl, msg = flags.get(f.index, ((), ""))
        r = FrameResult(
            f.index,
            f.truth.joints,
            f.truth.vertices,
            flags=fl,
            message=msg,
            healthy=fl != ("missing",),
        )
        write_frame(root / "t", r)
    track = read_track(root / "t")
    return track, evaluate(track, cap, silhouettes=False, surface_frames=0)


def test_frame_ranges():
    assert frame_ranges([7, 3, 4, 5, 12, 40, 41]) == "3–5, 7, 12, 40–41"
    assert frame_ranges([]) == ""
    assert frame_ranges(range(0, 40, 2), limit=3) == "0, 2, 4, … (17 more)"


def test_skipped_and_flagged_frames_say_why(scored):
    track, ev = scored
    ev = replace(ev, out_of_view=np.array([0, 3]))  # as if the subject left the view there
    rows = {r[0]: r for r in frame_rows(ev, track)}
    assert rows["not scored: out of view"][1:3] == (2, "0, 3")
    assert "leaves a camera's image" in rows["not scored: out of view"][3]
    assert rows["flagged: lost"][1:] == (1, "1", "left arm below the quality threshold")
    assert rows["flagged: missing"][2] == "2" and "coasted" in rows["flagged: missing"][3]
    titles = [t.title for t in evaluation_tables(ev, track=track)]
    assert "Frames not scored or flagged" in titles
    # nothing to say: no table
    clean = replace(ev, out_of_view=np.zeros(0, np.int64))
    assert "Frames not scored or flagged" not in [t.title for t in evaluation_tables(clean)]


def test_frames_the_two_way_pass_changed_are_listed_and_marked(scored, synth_capture):
    from meshmocap.apps.report.page import report_html
    from meshmocap.apps.report.player import player_from_tracks

    track, ev = scored
    two_way = {
        "changed": [
            {"frames": [1, 2], "keyframe": 3, "direction": "backward", "limbs": ["left_arm"]}
        ]
    }
    track = replace(track, meta={**track.meta, "two_way": two_way})
    rows = {r[0]: r for r in frame_rows(ev, track)}
    _, n, frames, why = rows["changed: two-way pass"]
    assert (n, frames) == (2, "1–2") and "keyframe 3, backward: left_arm" in why
    # the player's timeline: frame 1 lost and changed, frame 2 changed
    cap = synth_capture("walk", stop=4)
    player = player_from_tracks(cap, [track], hull_points=0, truth=False)
    assert player.tracks[0].marks.tolist() == [0, 3, 2, 0]
    html = report_html(title="t", players=[player])
    assert html.count("<rect") == 2 and "changed by the two-way pass" in html
    assert 'class="mm-timeline"' in html


def _bones(ev):
    (bones,) = [t for t in evaluation_tables(ev) if t.title.startswith("Bone lengths")]
    return bones


def test_bone_spread_fixed_by_construction_is_explained(scored):
    _, ev = scored  # the truth's bones are rigid: every std is 0
    notes = _bones(ev).notes
    assert len(notes) == 1 and "std 0.0 for every bone by construction" in notes[0]
    assert "patch tracker's joint read-out" in notes[0]
    assert "articulated ICP" in _bones(replace(ev, method="articulated_icp")).notes[0]
    wobble = 1 + 0.01 * np.sin(np.arange(len(ev.bones.lengths)))[:, None]  # every bone moves
    moving = replace(ev.bones, lengths=ev.bones.lengths * wobble)
    assert _bones(replace(ev, bones=moving)).notes == ()


def test_comparison_table_defines_worst_frame_and_missing_silhouettes(scored):
    _, ev = scored
    t = comparison_table([ev], no_silhouettes="the demo skips it to save time")
    row = dict(zip(t.headers, t.rows[0], strict=True))
    k = int(np.argmax(ev.joints.per_frame))
    assert row["worst frame (mm)"] == pytest.approx(ev.joints.per_frame[k])
    assert row["worst frame"] == int(ev.joints.frames[k])
    assert np.isnan(row["silhouette (%)"])
    assert any(n.startswith("worst frame: the frame with the largest mean error") for n in t.notes)
    assert "silhouette (%): n/a: not measured, the demo skips it to save time." in t.notes
    html = table_html(t)
    assert html.count('class="mm-note"') == 2 and 'colspan="10"' in html
