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
from meshmocap.trackers.driver import track_sequence
from meshmocap.trackers.options import TrackOptions
from meshmocap.trackers.registry import make_tracker

N = 6  # frames of the walk


@pytest.fixture(scope="module")
def walk(synth_capture):
    """The session's neutral_5k walk, :data:`N` frames."""
    return synth_capture("walk", stop=N)


@pytest.fixture(scope="module")
def offline(walk, tmp_path_factory):
    """The same capture tracked the ordinary way (articulated ICP)."""
    out = tmp_path_factory.mktemp("offline")
    t = load_template("neutral_5k")
    return track_sequence(
        make_tracker("articulated_icp", template=t), t, walk, out, TrackOptions(show_progress=False)
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
    assert meta["live"] is True and meta["template_source"] == "capture"
    assert "frames" not in meta and meta["input"]["units"] == "m" and meta["fps"] == 60.0
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
    from meshmocap import api

    live, out = tmp_path / "live", tmp_path / "track"
    reported, returned = threading.Event(), threading.Event()
    real = api.track

    def spy(*args, on_frame, **kwargs):  # the command's own report, then the signal
        def told(r):
            on_frame(r)
            if r.index == 2:
                reported.set()

        return real(*args, on_frame=told, **kwargs)

    monkeypatch.setattr(api, "track", spy)

    def interrupt():  # Ctrl-C once three frames are reported (the run would wait a minute)
        reported.wait()
        if not returned.is_set():
            signal.pthread_kill(threading.main_thread().ident, signal.SIGINT)

    # Ctrl-C raises KeyboardInterrupt, as in a command's own process (pytest-xdist's
    # workers ignore SIGINT)
    handler = signal.signal(signal.SIGINT, signal.default_int_handler)
    stopper = threading.Thread(target=interrupt, daemon=True)
    stopper.start()
    th = _studio(walk.path, live, range(3))
    args = ["track", str(live), "--method", "articulated_icp", "--out", str(out)]
    try:
        assert main([*args, "--follow", "--idle", "60"]) == 0
    finally:
        returned.set()
        reported.set()  # release the waiter if frame 2 never came
        signal.signal(signal.SIGINT, handler)
    th.join()
    stopper.join()
    assert "Ctrl-C: tracked 3 frames" in capsys.readouterr().out
    assert done_frames(out) == [0, 1, 2]
    assert not (out / ".meshmocap.lock").exists()  # released and removed


@pytest.mark.slow
def test_a_mesh_folder_and_a_stop_callback(walk, tmp_path):
    """Mesh files numbered as ``track`` numbers them (m_2 is frame 2, m_10 frame 10),
    written then renamed; a file numbered before frames already tracked is left out;
    stop() ends the run. Through the Python API: open_capture(follow=True), track."""
    import meshmocap

    live, out = tmp_path / "meshes", tmp_path / "track"
    live.mkdir()
    meshes = [walk[i].hull_mesh for i in range(3)]
    seen = []
    reported = [threading.Event(), threading.Event()]  # frame k reported: write the next

    def report(r):
        seen.append(r)
        reported[min(len(seen), 2) - 1].set()

    def studio():
        for k, name in enumerate(["m_2.ply", "m_10.ply"]):
            write_mesh(live / f".{name}", *meshes[k])
            os.replace(live / f".{name}", live / name)
            reported[k].wait()
        write_mesh(live / ".m_1.ply", *meshes[2])  # numbered before frames tracked
        os.replace(live / ".m_1.ply", live / "m_1.ply")

    th = threading.Thread(target=studio, daemon=True)
    th.start()
    cap = meshmocap.open_capture(
        live, follow=True, stop=lambda: len(seen) >= 2 and not th.is_alive()
    )
    result = meshmocap.track(
        cap, method="articulated_icp", template="neutral_5k", out=out, on_frame=report
    )
    th.join()
    assert [r.index for r in seen] == [2, 10] and list(result.frames) == [2, 10]
    assert cap.grow() == 0 and cap.skipped == [live / "m_1.ply"]  # listed, left out
    # tracked, not coasted (the lost-limb rule's verdict on a hull is not live mode's claim)
    bad = {"failed", "missing"}
    assert all(cap.written(r.index) <= time.time() and not bad & set(r.flags) for r in seen)
    assert not any(bad & set(f) for f in read_track(out).flags)


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
    (tmp_path / "meshes").mkdir()  # no frame comes: one line, exit 2
    assert main(["track", str(tmp_path / "meshes"), "--follow", "--idle", "0.3", "--out", out]) == 2
    err = capsys.readouterr().err
    assert f"no frame of {tmp_path / 'meshes'} holds a body yet (0 frames" in err
    assert "no new frame for 0.3 s (--idle)" in err and err.count("\n") == 1


# ------------------------------------------------- a mesh folder in centimetres, Y up

FORMATS = ("bvh", "c3d", "trc", "gltf", "glb", "csv")


@pytest.fixture(scope="module")
def studio(tmp_path_factory) -> Path:
    """Six OBJ frames of a walk in centimetres with Y up (``studio/meshes``) and their
    truth (``studio/reference``): :func:`meshmocap.api.example_capture`."""
    from meshmocap.api import example_capture

    return example_capture(tmp_path_factory.mktemp("cm") / "studio", n_frames=N)


def _writer(src: Path, dst: Path, *, delay: float = 0.05) -> threading.Thread:
    """Start a thread that copies the mesh files of ``src`` into ``dst`` one by one
    (hidden name, then rename), as a studio exporting a take would."""
    dst.mkdir(parents=True, exist_ok=True)

    def write():
        for f in sorted(src.iterdir()):
            time.sleep(delay)
            shutil.copyfile(f, dst / f".{f.name}")
            os.replace(dst / f".{f.name}", dst / f.name)

    th = threading.Thread(target=write, daemon=True)
    th.start()
    return th


def test_a_folder_in_cm_and_y_up_written_while_followed_tracks_every_frame(
    studio, tmp_path, capsys
):
    """Live mode is ``track``: the files' axes and units detected from the first frame,
    the body estimated from the first frames (no --template needed), every frame tracked,
    ``track.json`` recording the axes, units and rate; the track then exports to every
    format and is scored against the truth like any other."""
    live, out = tmp_path / "live", tmp_path / "track"
    th = _writer(studio / "meshes", live)
    argv = ["track", str(live), "--follow", "--idle", "1.5", "--fps", "30", "--out", str(out)]
    assert main([*argv, "--method", "articulated_icp"]) == 0
    th.join()
    said = capsys.readouterr().out
    assert f"{live}: Y up, cm, a body 1.7" in said and "template estimated from the capture" in said
    assert "no new frame for 1.5 s: tracked 6 frames" in said
    assert done_frames(out) == list(range(N))
    meta = json.loads((out / "track.json").read_text())
    assert meta["live"] is True and meta["fps"] == 30.0
    assert (meta["input"]["up"], meta["input"]["units"], meta["input"]["scale"]) == (
        "y",
        "cm",
        0.01,
    )
    track = read_track(out)
    truth = np.stack(
        [np.load(p)["joints"] for p in sorted((studio / "reference/truth").glob("0*"))]
    )
    assert np.linalg.norm(track.joints - truth, axis=2).mean() < 0.05  # metres, Z up
    for fmt in FORMATS:
        assert main(["export", str(out), "--out", str(tmp_path / f"live.{fmt}")]) == 0
        assert f"({fmt}, 6 frames at 30 fps" in capsys.readouterr().out
    ref = str(studio / "reference")
    assert (
        main(["eval", ref, str(out), "--force", "--no-silhouettes", "--out", str(tmp_path / "e")])
        == 0
    )
    assert "6 frames" in capsys.readouterr().out
    old = {k: v for k, v in meta.items() if k != "live"}  # as live tracks were written before
    (out / "track.json").write_text(json.dumps({**old, "frames": "follow"}))
    assert main(["export", str(out), "--out", str(tmp_path / "old.csv")]) == 0
    assert main(["eval", ref, str(out), "--force", "--no-silhouettes"]) == 0


def test_a_finished_folder_tracked_live_is_tracked_as_track_tracks_it(studio, tmp_path, capsys):
    """The files are all there before: live mode and ``track`` give the same track (the
    same detection, body, start and per-frame function)."""
    argv = ["--method", "articulated_icp", "--fps", "30"]
    meshes = str(studio / "meshes")
    assert main(["track", meshes, *argv, "--out", str(tmp_path / "a")]) == 0
    assert (
        main(["track", meshes, *argv, "--follow", "--idle", "0.5", "--out", str(tmp_path / "b")])
        == 0
    )
    a, b = read_track(tmp_path / "a"), read_track(tmp_path / "b")
    assert list(b.frames) == list(a.frames) == list(range(N))
    np.testing.assert_allclose(b.joints, a.joints, atol=1e-9)
    same = ("input", "fps", "template", "template_source", "tracked_vertices", "options")
    assert {k: b.meta[k] for k in same} == {k: a.meta[k] for k in same}


@pytest.mark.slow
def test_a_given_template_on_a_folder_in_cm_and_y_up(studio, tmp_path, capsys):
    """The case that tracked 0 frames and exited 0 (the files were read as metres with
    Z up): a bundled template, the axes given, every frame tracked."""
    out = tmp_path / "t"
    argv = ["track", str(studio / "meshes"), "--follow", "--idle", "0.5", "--out", str(out)]
    extra = [
        "--template",
        "neutral_5k",
        "--up",
        "y",
        "--units",
        "cm",
        "--method",
        "articulated_icp",
    ]
    assert main([*argv, *extra]) == 0
    assert "tracked 6 frames" in capsys.readouterr().out
    track = read_track(out)
    assert track.healthy.all() and list(track.frames) == list(range(N))
