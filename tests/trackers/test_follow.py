"""Live tracking (``track FOLDER --follow``): a writer thread plays a studio writing frames
into a folder while the tracker follows it, in-process."""

import json
import os
import shutil
import signal
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from meshmocap.body.template import load_template
from meshmocap.cli import main
from meshmocap.io.meshes import write_mesh
from meshmocap.io.results import done_frames, read_track
from meshmocap.studio.synth import SynthSpec, synthesize
from meshmocap.trackers.driver import track_sequence
from meshmocap.trackers.follow import follow_sequence
from meshmocap.trackers.registry import make_tracker

N = 6  # frames of the walk


@pytest.fixture(scope="module")
def walk(tmp_path_factory):
    out = tmp_path_factory.mktemp("walk")
    return synthesize(
        out, SynthSpec(motion="walk", template="neutral_5k", stop=N), show_progress=False
    )


@pytest.fixture(scope="module")
def offline(walk, tmp_path_factory):
    """The same capture tracked the ordinary way (articulated ICP)."""
    out = tmp_path_factory.mktemp("offline")
    t = load_template("neutral_5k")
    return track_sequence(
        make_tracker("articulated_icp", template=t), t, walk, out, show_progress=False
    )


def _studio(src: Path, dst: Path, frames, *, delay: float = 0.05) -> threading.Thread:
    """Start a thread that writes the capture ``src``'s hull files ``frames`` into ``dst``
    one by one (hidden name, then rename), as a studio would; everything but the hulls is
    there before the first frame."""
    if not (dst / "capture.json").exists():
        shutil.copytree(src, dst, ignore=shutil.ignore_patterns("hulls"), dirs_exist_ok=True)

    def write():
        (dst / "hulls").mkdir(exist_ok=True)
        for i in frames:
            time.sleep(delay)
            name = f"{i:05d}.npz"
            shutil.copyfile(src / "hulls" / name, dst / "hulls" / f".{name}")
            os.replace(dst / "hulls" / f".{name}", dst / "hulls" / name)

    th = threading.Thread(target=write, daemon=True)
    th.start()
    return th


@pytest.mark.slow
def test_follow_tracks_frames_as_written_and_resumes(walk, offline, tmp_path, capsys):
    """Frames written one by one are tracked as they come, with the offline results;
    a second run resumes after the last frame written."""
    live, out = tmp_path / "live", tmp_path / "track"
    th = _studio(walk.path, live, range(4))
    args = ["track", str(live), "--method", "articulated_icp", "--out", str(out), "--follow"]
    assert main([*args, "--idle", "1.5"]) == 0
    th.join()
    text = capsys.readouterr().out
    assert [f"frame {i}:" in text for i in range(1, 4)] == [True] * 3
    assert "latency" in text and "no new frame for 1.5 s: tracked 4 frames" in text
    assert done_frames(out) == [0, 1, 2, 3]
    meta = json.loads((out / "track.json").read_text())  # the capture's own template
    assert meta["frames"] == "follow" and meta["template_source"] == "capture"
    th = _studio(walk.path, live, range(4, N))
    assert main([*args, "--idle", "1.5"]) == 0  # resumes
    th.join()
    assert "tracked 2 frames" in capsys.readouterr().out
    track = read_track(out)
    assert list(track.frames) == list(range(N))
    # the same numbers as tracking the finished capture (same code path, same state)
    assert np.abs(track.joints - offline.joints).max() < 1e-9
    assert read_track(out).healthy.all()


def test_ctrl_c_stops_with_every_finished_frame_kept(walk, tmp_path, capsys, monkeypatch):
    """Ctrl-C once the third frame is reported; every reported frame is kept. Events, not
    clocks, order the threads: the interrupt waits for the report of frame 2 however
    slowly a loaded machine tracks, and is never sent once the command has returned."""
    from meshmocap.trackers import follow

    live, out = tmp_path / "live", tmp_path / "track"
    reported, returned = threading.Event(), threading.Event()
    real = follow.follow_sequence

    def spy(*args, report, **kwargs):  # the command's own report, then the signal
        def told(f):
            report(f)
            if f.index == 2:
                reported.set()

        return real(*args, report=told, **kwargs)

    monkeypatch.setattr(follow, "follow_sequence", spy)

    def interrupt():  # Ctrl-C once three frames are reported (the run would wait a minute)
        reported.wait()
        if not returned.is_set():
            signal.pthread_kill(threading.main_thread().ident, signal.SIGINT)

    stopper = threading.Thread(target=interrupt, daemon=True)
    stopper.start()
    th = _studio(walk.path, live, range(3))
    args = ["track", str(live), "--method", "articulated_icp", "--out", str(out)]
    try:
        assert main([*args, "--follow", "--idle", "60"]) == 0
    finally:
        returned.set()
        reported.set()  # release the waiter if frame 2 never came
    th.join()
    stopper.join()
    assert "Ctrl-C: tracked 3 frames" in capsys.readouterr().out
    assert done_frames(out) == [0, 1, 2]


@pytest.mark.slow
def test_a_mesh_folder_and_a_stop_callback(walk, tmp_path):
    """Mesh files in natural order (m_2 before m_10), written then renamed; a name sorting
    before frames already tracked is left out; stop() ends the run."""
    live, out = tmp_path / "meshes", tmp_path / "track"
    live.mkdir()
    t = load_template("neutral_5k")
    meshes = [walk[i].hull_mesh for i in range(3)]
    seen = []
    reported = [threading.Event(), threading.Event()]  # frame k reported: write the next

    def report(f):
        seen.append(f)
        reported[min(len(seen), 2) - 1].set()

    def studio():
        for k, name in enumerate(["m_2.ply", "m_10.ply"]):
            write_mesh(live / f".{name}", *meshes[k])
            os.replace(live / f".{name}", live / name)
            reported[k].wait()
        write_mesh(live / ".m_1.ply", *meshes[2])  # sorts before m_2: would renumber
        os.replace(live / ".m_1.ply", live / "m_1.ply")

    th = threading.Thread(target=studio, daemon=True)
    th.start()
    tracked = follow_sequence(
        make_tracker("articulated_icp", template=t),
        t,
        live,
        out,
        report=report,
        stop=lambda: len(seen) >= 2 and not th.is_alive(),
    )
    th.join()
    assert tracked == [0, 1] and [f.index for f in seen] == [0, 1]
    assert all(f.latency >= f.seconds >= 0 and not f.flags for f in seen[1:])
    assert read_track(out).healthy.all()


def test_follow_needs_one_folder_and_idle_needs_follow(walk, tmp_path, capsys):
    out = str(tmp_path / "t")
    assert main(["track", str(walk.path), "--idle", "2", "--out", out]) == 2
    assert "--idle goes with --follow" in capsys.readouterr().err
    assert main(["track", str(walk.path), "--follow", "--frames", "0:2", "--out", out]) == 2
    assert "give one folder" in capsys.readouterr().err
    assert (
        main(
            ["track", str(tmp_path / "none"), "--follow", "--out", out, "--template", "neutral_5k"]
        )
        == 2
    )
    assert "is not a folder" in capsys.readouterr().err
    (tmp_path / "meshes").mkdir()  # no capture.json naming a template, no frame yet
    assert main(["track", str(tmp_path / "meshes"), "--follow", "--out", out]) == 2
    assert "give --template" in capsys.readouterr().err
