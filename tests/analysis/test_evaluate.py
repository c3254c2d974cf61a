"""Evaluating a track against a capture: known perturbations give known errors."""

from dataclasses import replace

import numpy as np
import pytest

from meshmocap.analysis.evaluate import evaluate, summary
from meshmocap.apps.files.evaluation import write_evaluation
from meshmocap.cli import main
from meshmocap.errors import InputError
from meshmocap.io.capture import read_truth, write_truth
from meshmocap.io.results import FrameResult, read_track, start_track, write_frame


@pytest.fixture(scope="module")
def capture(synth_capture):
    return synth_capture("walk", stop=4)


def _track(capture, out, shift):
    """A 'track' that is the truth moved by ``shift`` metres."""
    from meshmocap.body.template import EVAL_NAMES, EVAL_PARENTS

    meta = {
        "method": "truth+shift",
        "template": "neutral_5k",
        "eval_names": list(EVAL_NAMES),
        "eval_parents": EVAL_PARENTS.tolist(),
    }
    start_track(out, meta, capture.truth_faces, resume=False)
    for f in capture:
        t = f.truth
        write_frame(out, FrameResult(f.index, t.joints + shift, t.vertices + shift, seconds=0.01))
    return read_track(out)


def test_a_shifted_truth_scores_its_shift(capture, tmp_path):
    shift = np.array([0.003, 0.004, 0.0])  # 5 mm
    ev = evaluate(_track(capture, tmp_path / "tr", shift), capture, surface_frames=2)
    assert ev.joints.overall.mean == pytest.approx(5.0, abs=1e-6)  # mm, exact up to rounding
    assert ev.joints14.overall.max == pytest.approx(5.0, abs=1e-6)
    assert ev.correspondence.overall.mean == pytest.approx(5.0, abs=1e-3)  # float32 vertices
    # bone lengths: the truth's own (the spine bends, so pelvis–thorax varies by ~1 µm here)
    assert ev.bones.std.max() < 1e-3
    # surface distance of a 5 mm shift: between 0 and 5 mm (tangential shifts cost nothing)
    assert 0.5 < ev.surface.mean.mean() < 5.0 and ev.surface.against == "truth"
    # silhouettes: a 5 mm shift of a ~200 px tall body moves the outline by < 1 px
    assert 0.0 < ev.silhouettes.overall < 0.05
    files = write_evaluation(ev, tmp_path / "report")
    assert all(p.is_file() and p.stat().st_size > 0 for p in files)


def test_exact_truth_scores_zero(capture, tmp_path):
    ev = evaluate(
        _track(capture, tmp_path / "tr", 0.0), capture, silhouettes=False, surface_frames=0
    )
    assert ev.joints.overall.max == 0.0 and ev.silhouettes is None and ev.surface is None


def test_a_track_without_a_start_record_reports_its_start_unknown(capture, tmp_path):
    """A track made before starts were recorded: its first message is not parsed."""
    track = _track(capture, tmp_path / "tr", 0.0)
    track = replace(track, messages=("init auto: 02_02:2@0°, fit score 34.5 mm",) * 4)
    ev = evaluate(track, capture, silhouettes=False, surface_frames=0)
    assert ev.start is None and ev.init == "truth (start unknown)"
    assert "; init truth (start unknown)" in summary(ev)


def test_eval_command(capture, tmp_path, capsys):
    _track(capture, tmp_path / "tr", np.array([0.0, 0.0, 0.01]))
    assert (
        main(
            [
                "eval",
                str(capture.path),
                str(tmp_path / "tr"),
                "--out",
                str(tmp_path / "r"),
                "--surface-frames",
                "1",
            ]
        )
        == 0
    )
    out = capsys.readouterr().out
    assert "3D joint error" in out and (tmp_path / "r" / "joint_errors.csv").is_file()


def test_track_frames_missing_from_the_capture(capture, tmp_path):
    tr = _track(capture, tmp_path / "tr", 0.0)
    write_frame(tmp_path / "tr", FrameResult(99, tr.joints[0], tr.vertices[0]))
    with pytest.raises(InputError, match=r"\[99\]"):
        evaluate(read_track(tmp_path / "tr"), capture)


def test_frames_out_of_the_cameras_view_are_not_scored(capture, tmp_path):
    """A subject leaving a camera's image is not scored (its hull is truncated): a frame
    whose true surface is moved 20 m sideways is listed as out of view and skipped; the
    others still score their exact truth as zero."""
    import shutil

    from meshmocap.io.capture import open_capture

    copy = tmp_path / "cap"
    shutil.copytree(capture.path, copy)
    track = _track(capture, tmp_path / "tr", 0.0)
    truth = sorted((copy / "truth").glob("*.npz"))[1]
    t = read_truth(truth)
    write_truth(truth, replace(t, vertices=t.vertices + np.array([20.0, 0.0, 0.0])))
    moved = open_capture(copy)
    ev = evaluate(track, moved, silhouettes=False, surface_frames=0)
    assert ev.out_of_view.tolist() == [track.frames[1]]
    assert track.frames[1] in ev.joints.skipped.tolist()
    assert ev.joints.overall.max == 0.0 and len(ev.joints.frames) == len(track.frames) - 1
    assert "not scored" in summary(ev)
    everything = evaluate(track, moved, silhouettes=False, surface_frames=0, in_view_only=False)
    assert len(everything.out_of_view) == 0 and everything.correspondence.overall.max > 1e4


def _mesh_folder_track(capture, folder, out, shift, *, cage_body=None):
    """The capture's true surfaces written as a folder of PLY meshes (a clean 4D capture)
    and a 'track' of it that is those surfaces moved by ``shift`` metres."""
    from meshmocap.body.template import EVAL_NAMES, EVAL_PARENTS
    from meshmocap.io.capture import SequenceCapture
    from meshmocap.io.meshes import write_mesh

    folder.mkdir()
    for f in capture:
        write_mesh(folder / f"{f.index:05d}.ply", f.truth.vertices, capture.truth_faces)
    meta = {
        "method": "files+shift",
        "template": "subject",
        "capture": str(folder),
        "eval_names": list(EVAL_NAMES),
        "eval_parents": EVAL_PARENTS.tolist(),
        **({"cage_body": cage_body} if cage_body else {}),
    }
    start_track(out, meta, capture.truth_faces, resume=False)
    for f in capture:
        write_frame(out, FrameResult(f.index, f.truth.joints + shift, f.truth.vertices + shift))
    return read_track(out), SequenceCapture(folder)


def test_a_clean_4d_capture_is_scored_per_vertex_per_frame_against_its_input_meshes(
    capture, tmp_path
):
    shift = np.array([0.0, 0.006, 0.008])  # 10 mm
    track, seq = _mesh_folder_track(
        capture, tmp_path / "seq", tmp_path / "tr", shift, cage_body="reference"
    )
    ev = evaluate(track, seq, silhouettes=False, surface_frames=2)
    assert ev.correspondence.overall.mean == pytest.approx(10.0, abs=1e-3)  # float32 files
    assert ev.surface.against == "input meshes"
    text = summary(ev)
    assert "Surface distance to the input meshes" in text and "to the hull" not in text
    assert "cage built on the reference body" in text
    files = write_evaluation(ev, tmp_path / "ev")
    per = tmp_path / "ev" / "vertex_errors_per_frame.csv"
    assert per in files and (tmp_path / "ev" / "vertex_error_per_frame.png") in files
    rows = per.read_text().splitlines()
    assert rows[0] == "frame,status,mean_mm" and len(rows) == 1 + len(track.frames)
    values = np.array([float(r.split(",")[2]) for r in rows[1:]])
    np.testing.assert_allclose(values, 10.0, atol=1e-3)


def test_a_track_that_failed_everywhere_is_scored_without_a_warning(capture, tmp_path):
    """Every frame failed (NaN): the scores are n/a, and no numpy warning escapes
    (filterwarnings=error turns one into a failure)."""
    track, seq = _mesh_folder_track(capture, tmp_path / "seq", tmp_path / "tr", 0.0)
    track = replace(track, vertices=np.full_like(track.vertices, np.nan))
    ev = evaluate(track, seq, silhouettes=False, surface_frames=2)
    assert len(ev.correspondence.frames) == 0 and np.isnan(ev.correspondence.overall.mean)
    assert "cage built" not in summary(ev)
    files = write_evaluation(ev, tmp_path / "ev")
    rows = (tmp_path / "ev" / "vertex_errors_per_frame.csv").read_text().splitlines()
    assert all(r.split(",")[1] == "failed" for r in rows[1:]) and all(p.is_file() for p in files)
