"""``meshmocap track`` on mesh files as studios hand them out: frames numbered by their
file names (a gap is a missing frame, a stray copy is refused), the files' up axis, units
and frame rate recorded in ``track.json`` and read back by ``eval`` and ``report``."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from meshmocap.analysis.evaluate import evaluate
from meshmocap.analysis.metrics import correspondence_error
from meshmocap.cli import main
from meshmocap.io.capture import Capture
from meshmocap.io.meshes import write_mesh
from meshmocap.io.results import input_frame, open_tracked_capture, read_track

ICP = ["--method", "articulated_icp", "--max-iter", "2", "--template", "neutral_5k"]


@pytest.fixture(scope="module")
def cap(synth_capture) -> Path:
    """A 4-frame synthetic capture (neutral_5k walk at 30 fps, 2 cm voxels)."""
    return synth_capture("walk", stop=4, fps=30.0, voxel_size=0.02).path


def _truth_files(cap: Path, folder: Path, numbers, *, up="y", mm=True) -> dict[int, np.ndarray]:
    """The capture's true surfaces (neutral_5k's connectivity: a clean 4D capture) written as
    ``NNNNN.ply`` for ``numbers``, in millimetres and Y up; returns them in metres, Z up."""
    folder.mkdir()
    c = Capture(cap)
    out = {}
    for i in numbers:
        V = c[i].truth.vertices
        write_mesh(folder / f"{i:05d}.ply", V * (1000 if mm else 1), c.truth_faces, up=up)
        out[i] = V
    return out


@pytest.mark.slow
def test_a_4d_capture_in_mm_and_y_up_is_scored_in_its_own_frame(cap, tmp_path, capsys):
    seq = tmp_path / "seq"
    truth = _truth_files(cap, seq, (0, 1, 3))  # frame 2 has no file
    out = tmp_path / "t"
    assert main(["track", str(seq), *ICP, "--fps", "25", "--out", str(out)]) == 0
    run = capsys.readouterr()
    assert "Y up, mm" in run.out and "25 fps" in run.out
    assert "1 frame number without a file (first 2)" in run.err
    meta = json.loads((out / "track.json").read_text())
    assert meta["fps"] == 25.0
    assert meta["input"] == {"up": "y", "units": "mm", "scale": 0.001, "offset": [0.0, 0.0, 0.0]}
    t = read_track(out)
    assert t.frames.tolist() == [0, 1, 2, 3]  # the gap kept in the numbering
    assert [("missing" in f) for f in t.flags] == [False, False, True, False]
    assert "no file of frame 2" in t.messages[2]
    # eval reads the files as track did, and scores every tracked vertex against the file's
    assert main(["eval", str(seq), str(out), "--surface-frames", "2"]) == 0
    said = capsys.readouterr().out
    assert "read as tracked (Y up, mm, 25 fps)" in said and "nan" not in said.lower()
    ev = evaluate(t, open_tracked_capture(t.meta, seq), silhouettes=False, surface_frames=0)
    k = [0, 1, 3]
    want = correspondence_error(t.vertices[k], np.stack([truth[i] for i in k]))
    assert ev.correspondence is not None and ev.correspondence.frames.tolist() == [0, 1, 3]
    assert ev.correspondence.overall.mean == pytest.approx(want.overall.mean, abs=1e-3)
    assert ev.correspondence.overall.mean < 100.0  # the files, not a frame 1000× off
    # the report's input (its player's points) lies where the track is: within 0.1 mm
    V = open_tracked_capture(t.meta)[3].hull_mesh[0]  # the capture recorded in track.json
    assert np.abs(V - truth[3]).max() < 1e-4
    assert input_frame(t.meta).describe() == "Y up, mm, 25 fps"


@pytest.mark.slow
def test_a_report_shows_the_input_where_the_track_is(cap, tmp_path):
    from meshmocap.apps.report.page import build_report

    seq = tmp_path / "seq"
    _truth_files(cap, seq, (0, 1))
    out = tmp_path / "t"
    assert main(["track", str(seq), *ICP, "--out", str(out)]) == 0
    html = build_report(tmp_path / "r.html", seq, [out], silhouettes=False, surface_frames=1)
    text = html.read_text()
    assert "Surface distance to the input meshes" in text
    ev = evaluate(read_track(out), open_tracked_capture(read_track(out).meta, seq))
    # the surface of the tracked mesh is near the input's (mm, not the 786 of a Z-up reread)
    assert ev.surface is not None and ev.surface.mean.max() < 60.0


@pytest.mark.slow
def test_track_without_fps_records_none_and_files_of_every_other_frame_miss_none(cap, tmp_path):
    seq = tmp_path / "seq"
    _truth_files(cap, seq, (0, 2), up="z", mm=False)
    out = tmp_path / "t"
    assert main(["track", str(seq), *ICP, "--out", str(out)]) == 0
    meta = json.loads((out / "track.json").read_text())
    assert "fps" not in meta and input_frame(meta).fps is None
    assert meta["input"]["up"] == "z" and meta["input"]["units"] == "m"
    t = read_track(out)
    assert t.frames.tolist() == [0, 2] and not any(t.flags)


@pytest.mark.parametrize(
    ("names", "bad"),
    [
        (["00000.ply", "00001.ply", "00001 (1).ply"], "00001 (1).ply: not a frame number"),
        (["00000.ply", "00001.ply", "00001_1.ply"], "00001_1.ply: not a frame number"),
        (["mesh_1.ply", "mesh_01.ply"], "frame 1 again"),
    ],
)
def test_a_name_that_is_not_a_frame_number_is_refused_in_one_line(
    cap, tmp_path, capsys, names, bad
):
    seq = tmp_path / "seq"
    seq.mkdir()
    c = Capture(cap)
    for k, name in enumerate(names):
        write_mesh(seq / name, c[min(k, 3)].truth.vertices, c.truth_faces)
    assert main(["track", str(seq), *ICP, "--out", str(tmp_path / "t")]) == 2
    err = capsys.readouterr().err.strip()
    assert bad in err and len(err.splitlines()) == 1


@pytest.mark.slow
def test_a_point_cloud_folder_needs_no_template(cap, tmp_path, capsys):
    import trimesh

    seq = tmp_path / "clouds"
    seq.mkdir()
    c = Capture(cap)
    for f in c:  # the hulls' vertices: no faces, no normals
        cloud = trimesh.PointCloud(f.hull_mesh[0]).export(file_type="ply")
        (seq / f"{f.index:05d}.ply").write_bytes(cloud)
    out = tmp_path / "t"
    argv = ["track", str(seq), "--max-iter", "3", "--n-patches", "60", "--out", str(out)]
    assert main(argv) == 0
    said = capsys.readouterr().out
    assert "hulls or points" in said and "the shape space fitted to the points" in said
    t = read_track(out)
    assert t.meta["template_source"] == "estimated" and (out / "subject_pose.npz").is_file()
    assert t.messages[0].startswith("init template: the template was made from frame 0")
    err = np.linalg.norm(t.joints[0] - c[0].truth.joints, axis=1)
    trunk_and_legs = [0, 1, 2, 9, 10, 11, 12, 13, 14]  # an arm held by the body is
    assert err[trunk_and_legs].mean() < 0.03  # ambiguous in 4-camera hulls of 2 cm: metres


@pytest.mark.slow
def test_a_clean_4d_capture_starts_in_its_first_frames_pose(cap, tmp_path, capsys):
    seq = tmp_path / "seq"
    truth = _truth_files(cap, seq, (0, 1, 2, 3), up="z", mm=False)
    out = tmp_path / "t"
    argv = ["track", str(seq), "--method", "articulated_icp", "--max-iter", "3"]
    assert main([*argv, "--out", str(out)]) == 0
    assert "closed meshes of one connectivity" in capsys.readouterr().out
    t = read_track(out)
    assert t.messages[0].startswith("init template") and "in its rest pose" in t.messages[0]
    # the template is frame 0 rigged as it stands: vertex i is the file's vertex i
    ev = evaluate(t, open_tracked_capture(t.meta, seq), silhouettes=False, surface_frames=0)
    per = ev.correspondence.per_frame
    assert per[0] < 2.0 and np.all(per < 40.0)  # mm: frame 0 starts where it is
    assert np.abs(t.vertices[0] - truth[0]).max() < 0.01


def test_track_ends_with_where_a_frames_time_goes(cap, tmp_path, capsys):
    """The last line of ``track``: the median milliseconds per frame of each stage."""
    out = tmp_path / "t"
    assert main(["track", str(cap), *ICP, "--init", "truth", "--out", str(out)]) == 0
    last = capsys.readouterr().out.strip().splitlines()[-1]
    assert last.startswith("time per frame (median of 2): read ")
    for stage in ("observe", "step", "checks", "write"):
        assert f", {stage} " in last
    assert last.endswith(" ms in all")
