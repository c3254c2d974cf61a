"""The command line, run in-process."""

import json

import numpy as np
import pytest

from meshmocap.cli import main
from meshmocap.io.bvh import read_bvh


def test_templates_lists_the_bundled_bodies(capsys):
    assert main(["templates"]) == 0
    out = capsys.readouterr().out
    for name in ("neutral", "neutral_5k", "heavy_male", "small_female"):
        assert name in out


def test_retarget_writes_a_bvh_on_the_template_skeleton(tmp_path, capsys):
    out = tmp_path / "walk.bvh"
    assert (
        main(["retarget", "walk", "--template", "small_female", "--fps", "30", "--out", str(out)])
        == 0
    )
    m = read_bvh(out)
    assert m.skeleton.n_joints == 31 and m.fps == 30.0 and m.n_frames == 121
    assert "wrote" in capsys.readouterr().out


def test_retarget_a_cmu_clip(cmu, tmp_path):
    out = tmp_path / "35_01.bvh"
    assert main(["retarget", str(cmu / "35_01.amc"), "--out", str(out)]) == 0
    m = read_bvh(out)
    assert m.n_frames == 358 and np.isfinite(m.joint_positions).all()


def test_render_rest_pose_and_clip(tmp_path):
    assert (
        main(
            [
                "render",
                "--template",
                "neutral_5k",
                "--out",
                str(tmp_path / "rest"),
                "--width",
                "60",
                "--height",
                "80",
            ]
        )
        == 0
    )
    assert (tmp_path / "rest" / "frame_00000.png").is_file()
    args = ["render", "squat", "--template", "neutral_5k", "--fps", "10", "--frames", "0:12:3"]
    assert main([*args, "--out", str(tmp_path / "sq"), "--width", "60", "--height", "80"]) == 0
    assert len(list((tmp_path / "sq").glob("frame_*.png"))) == 4
    assert (tmp_path / "sq" / "contact_sheet.png").is_file()


@pytest.mark.slow
def test_demo_runs_on_bundled_defaults(tmp_path, capsys):
    assert main(["demo", "--out", str(tmp_path), "--seconds", "1", "--track-frames", "4"]) == 0
    assert (tmp_path / "walk.bvh").is_file()
    assert (tmp_path / "walk_heavy_male" / "contact_sheet.png").is_file()
    out = capsys.readouterr().out
    assert "meshmocap demo" in out and "articulated_icp" in out and "mean joint error" in out
    assert (tmp_path / "eval_patch" / "summary.txt").is_file()
    # the user's path: a performer the trackers are not told about, its body estimated
    assert "performer 'heavy_male', not told to the trackers; template estimated" in out
    for tracker in ("patch", "cage", "articulated_icp"):
        if tracker == "cage" and "cage not tracked: cage: no cage could be built" in out:
            continue  # a body estimated from 4 frames the cage cannot enclose: said, not fatal
        meta = json.loads((tmp_path / f"track_{tracker}" / "track.json").read_text())
        assert meta["template_source"] == "estimated"
        assert (tmp_path / f"track_{tracker}" / meta["template_file"]).is_file()
    for ext in ("bvh", "c3d", "trc", "glb", "csv"):  # exported as meshmocap export does
        assert (tmp_path / "exports" / f"walk_patch.{ext}").stat().st_size > 0
    assert "patch gait: none" in out  # 4 frames hold no step; said, not a traceback


@pytest.mark.parametrize(
    ("text", "message"),
    [
        (
            "HIERARCHY\nROOT a\n{\n OFFSET 0 0 0\n CHANNELS 3 Xposition Yposition Zposition\n}\n"
            "MOTION\nFrames: 2\nFrame Time: 0.1\n0 0 0\n",
            "bad.bvh",
        ),
        ("", "bad.bvh"),
    ],
)
def test_user_mistakes_give_one_line_and_status_2(tmp_path, capsys, text, message):
    bad = tmp_path / "bad.bvh"
    bad.write_text(text)
    assert main(["retarget", str(bad), "--out", str(tmp_path / "o.bvh")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("meshmocap: error:") and message in err and "\n" not in err
    assert not (tmp_path / "o.bvh").exists()  # nothing half-written


def test_missing_files_and_bad_options(tmp_path, capsys):
    assert main(["retarget", str(tmp_path / "nope.amc"), "--out", str(tmp_path / "o.bvh")]) == 2
    assert "does not exist" in capsys.readouterr().err
    assert main(["render", "walk", "--template", "nobody", "--out", str(tmp_path)]) == 2
    assert "neither a bundled template" in capsys.readouterr().err
    assert main(["render", "walk", "--frames", "a:b", "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert "START:STOP" in err and err.count("\n") == 1


def test_a_closed_pipe_ends_quietly(monkeypatch, tmp_path):
    """``meshmocap templates | head -1``: the reader closes the pipe; status 0, no
    traceback, and stdout is pointed at the null device for the final flush."""
    import io
    import os
    import sys

    sink = os.open(tmp_path / "sink", os.O_WRONLY | os.O_CREAT)

    class ClosedPipe(io.StringIO):
        def write(self, s):
            raise BrokenPipeError(32, "Broken pipe")

        def fileno(self):
            return sink

    monkeypatch.setattr(sys, "stdout", ClosedPipe())
    try:
        assert main(["templates"]) == 0  # BrokenPipeError would propagate otherwise
    finally:
        os.close(sink)


def test_frames_are_frame_numbers_and_restart_is_one_flag_everywhere(tmp_path, capsys):
    """A capture of frames 4..9: ``--frames 6:8`` is frames 6 and 7 for ``hull`` and
    ``track`` alike (not positions 6 and 7, which do not exist); ``--restart`` redoes the
    hulls (``--overwrite``, the old spelling, still works)."""
    cap, out = tmp_path / "cap", tmp_path / "track"
    assert main(["synth", str(cap), "--template", "neutral_5k", "--frames", "4:10"]) == 0
    assert main(["hull", str(cap), "--frames", "6:8", "--restart"]) == 0
    said = capsys.readouterr().out  # the frames asked for, not the folder's six
    assert f"\nhulls of 2 frames (6–7) in {cap / 'hulls'} (2 carved by this run" in said
    assert main(["hull", str(cap), "--frames", "5", "--overwrite"]) == 0
    assert "hulls of 1 frame (5) in" in capsys.readouterr().out
    assert main(["hull", str(cap)]) == 0
    assert "hulls of 6 frames in" in capsys.readouterr().out
    assert main(["hull", str(cap), "--frames", "20:30"]) == 2
    assert "selects none of the 6 frames (numbers 4..9)" in capsys.readouterr().err
    args = ["track", str(cap), "--method", "articulated_icp", "--out", str(out)]
    assert main([*args, "--init", "truth", "--frames", "6:8", "--max-iter", "2"]) == 0
    meta = json.loads((out / "track.json").read_text())
    assert meta["frames"] == [6, 7]
    assert main([*args, "--init", "truth", "--frames", "0:4"]) == 2
    assert "selects none of the 6 frames (numbers 4..9)" in capsys.readouterr().err
