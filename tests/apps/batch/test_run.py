"""meshmocap batch: captures named every way, Dask results bit-identical to tracking alone,
a worker killed mid-run, a bad capture among good ones, reruns, the serial fallback."""

import os
import signal
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from meshmocap.apps.batch import run as batch_module
from meshmocap.apps.batch.items import BatchItem, batch_items
from meshmocap.apps.batch.run import run_batch
from meshmocap.apps.batch.summary import SUMMARY_COLUMNS
from meshmocap.body.template import load_template
from meshmocap.cli import main
from meshmocap.errors import InputError, MeshmocapFileNotFoundError
from meshmocap.io.capture import Capture
from meshmocap.io.results import done_frames, frame_path
from meshmocap.io.start import Start
from meshmocap.trackers import driver
from meshmocap.trackers.driver import track_sequence
from meshmocap.trackers.options import TrackOptions
from meshmocap.trackers.registry import make_tracker

distributed = pytest.importorskip("distributed")

METHOD = "articulated_icp"  # the quickest tracker to set up
MOTIONS = {"walk": 5, "jog": 5, "squat": 10}


@pytest.fixture(scope="module", autouse=True)
def _starts_from_the_truth(tmp_path_factory):
    """Every track in this module starts from its capture's true first pose, which it finds
    in the first-pose cache as a user's second track of a capture does: a cache folder of
    this module's own (no other test reads these starts), filled by the tracks made in this
    process (:func:`alone`) and inherited by the Dask workers, which read it. The search
    itself is tested in tests/estimate/pose/; here it cost three searches (the walk, jog
    and squat), most of the module's time."""

    def truth(template, frame, options=None):
        return Start(int(frame.index), frame.truth.rotations, frame.truth.root, "truth")

    mp = pytest.MonkeyPatch()
    mp.setenv("MESHMOCAP_CACHE", str(tmp_path_factory.mktemp("batch_cache")))
    mp.setattr(driver, "_search_first_pose", truth)
    yield
    mp.undo()


@pytest.fixture(scope="module")
def captures(synth_capture, tmp_path_factory):
    """The three captures (the session's, at 30 fps with 2 cm hulls: the walk is
    ``small_walk``, whose first pose other tests search too), linked into one folder."""
    root = tmp_path_factory.mktemp("captures")
    for motion, n in MOTIONS.items():
        cap = synth_capture(motion, stop=n, fps=30.0, voxel_size=0.02)
        (root / motion).symlink_to(cap.path, target_is_directory=True)
    return root


@pytest.fixture(scope="module")
def alone(captures, tmp_path_factory):
    """``alone(motion)``: the folder of that capture tracked by itself in this process (what
    batch must reproduce), tracked at first use (the tests that are not slow need only the
    walk)."""
    root = tmp_path_factory.mktemp("alone")
    template = load_template("neutral_5k")

    def track(motion: str) -> Path:
        if not (root / motion / "track.json").is_file():
            track_sequence(
                make_tracker(METHOD, template=template),
                template,
                Capture(captures / motion),
                root / motion,
                TrackOptions(show_progress=False),
            )
        return root / motion

    return track


@pytest.fixture(scope="module")
def cluster(alone):
    """Two worker processes; every capture is tracked alone first, so that its start is in
    the module's cache before a worker looks for it."""
    for motion in MOTIONS:
        alone(motion)
    options = dict(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=":0")
    with distributed.LocalCluster(**options) as c, distributed.Client(c) as client:
        yield client


def _same_frames(a: Path, b: Path) -> None:
    """Every frame file of two tracks holds the same arrays, bit for bit (timings aside)."""
    assert done_frames(a) == done_frames(b) and done_frames(a)
    for i in done_frames(a):
        with np.load(frame_path(a, i)) as x, np.load(frame_path(b, i)) as y:
            assert set(x.files) == set(y.files)
            for key in x.files:
                if key != "seconds":
                    np.testing.assert_array_equal(x[key], y[key], err_msg=f"frame {i} {key}")


def _summary(out: Path) -> list[dict]:
    import csv

    with (out / "summary.csv").open() as f:
        return list(csv.DictReader(f))


@pytest.mark.slow
def test_dask_results_are_bit_identical_to_tracking_alone(captures, alone, cluster, tmp_path):
    expected = {motion: alone(motion) for motion in MOTIONS}
    items = batch_items([str(captures / "*")], method=METHOD)
    assert [i.name for i in items] == ["jog", "squat", "walk"]
    res = run_batch(items, tmp_path / "b", client=cluster, show_progress=False)
    assert res.mode == "dask"
    assert [s.status for s in res.summaries] == ["ok"] * 3
    for motion in MOTIONS:
        _same_frames(tmp_path / "b" / motion / "track", expected[motion])
    rows = _summary(tmp_path / "b")
    assert tuple(rows[0]) == SUMMARY_COLUMNS
    assert {r["name"]: int(r["frames"]) for r in rows} == MOTIONS
    # errors against the capture's truth, as meshmocap eval gives them: tracked from the
    # true first pose (the module's cache), every capture within 30 mm
    mm = {r["name"]: float(r["mean_mm"]) for r in rows}
    assert all(0 < mm[motion] < 30 for motion in MOTIONS), mm
    assert (tmp_path / "b" / "walk" / "eval" / "summary.txt").is_file()
    # a rerun redoes nothing: the finished captures' results are read back
    before = {m: (tmp_path / "b" / m / "result.json").stat().st_mtime_ns for m in MOTIONS}
    again = run_batch(items, tmp_path / "b", client=cluster, show_progress=False)
    assert [s.status for s in again.summaries] == ["ok"] * 3
    assert before == {m: (tmp_path / "b" / m / "result.json").stat().st_mtime_ns for m in MOTIONS}


@pytest.mark.slow
def test_a_worker_killed_mid_run_costs_a_retry_not_the_result(captures, alone, cluster, tmp_path):
    expected = alone("squat")
    items = batch_items([str(captures / "squat")], method=METHOD)
    out = tmp_path / "b"
    done = {}
    thread = threading.Thread(
        target=lambda: done.setdefault(
            "res", run_batch(items, out, client=cluster, show_progress=False)
        )
    )
    thread.start()
    frames = out / "squat" / "track"
    # wait for frame 2's file however long a loaded machine takes (no deadline to miss)
    while not frame_path(frames, 2).is_file() and thread.is_alive():
        time.sleep(0.05)
    assert len(done_frames(frames)) < MOTIONS["squat"], "tracked too fast to kill mid-run"
    busy = [w for w, keys in cluster.processing().items() if keys]
    assert len(busy) == 1
    pid = cluster.run(os.getpid, workers=busy)[busy[0]]
    os.kill(pid, signal.SIGKILL)
    thread.join()
    res = done["res"]
    (s,) = res.summaries
    assert s.status == "ok" and s.attempts == 2
    assert _summary(out)[0]["attempts"] == "2"
    _same_frames(frames, expected)


@pytest.mark.slow
def test_a_bad_capture_fails_alone_and_the_summary_names_its_error(captures, cluster, tmp_path):
    bad = tmp_path / "bad"
    bad.mkdir()
    (bad / "capture.json").write_text("{not json")
    items = batch_items([str(captures / "walk"), str(bad)], method=METHOD)
    res = run_batch(items, tmp_path / "b", client=cluster, show_progress=False)
    good, failed = res.summaries
    assert good.status == "ok" and good.frames == MOTIONS["walk"]
    assert failed.status == "failed" and "capture.json" in failed.error
    assert "\n" not in failed.error
    md = (tmp_path / "b" / "summary.md").read_text()
    assert "| bad | articulated_icp | default | failed |" in md  # never opened
    assert "| walk | articulated_icp | neutral_5k (named by capture.json) | ok |" in md


def test_without_dask_it_runs_serially_and_says_how_to_get_the_cluster(
    captures, alone, tmp_path, monkeypatch
):
    monkeypatch.setattr(batch_module, "have_dask", lambda: False)
    expected = alone("walk")
    items = batch_items([str(captures / "walk")], method=METHOD)
    lines = []
    res = run_batch(items, tmp_path / "b", show_progress=False, log=lines.append)
    assert res.mode == "serial" and res.summaries[0].status == "ok"
    assert 'pip install -e ".[cluster]" runs them in parallel' in lines[0]
    _same_frames(tmp_path / "b" / "walk" / "track", expected)
    assert lines[-1].startswith("done walk: 5 frames, 0 flagged")


def test_items_from_folders_globs_lists_and_manifests(captures, tmp_path):
    (tmp_path / "list.txt").write_text(f"# my session\n{captures / 'walk'}\n\n{captures}/j*\n")
    items = batch_items([str(tmp_path / "list.txt")], method="patch", frames="0:3")
    assert [(i.name, i.method, i.frames) for i in items] == [
        ("walk", "patch", "0:3"),
        ("jog", "patch", "0:3"),
    ]
    (tmp_path / "m.csv").write_text(
        "capture,method,template,frames\n"
        f"{captures / 'walk'},cage,,\n{captures / 'walk'},,neutral,1:4\nsquat,,,\n"
    )
    (tmp_path / "squat").symlink_to(captures / "squat")
    items = batch_items([str(tmp_path / "m.csv")], method="patch", template="neutral_5k")
    assert items == [
        BatchItem("walk", str(captures / "walk"), "cage", "neutral_5k", ""),
        BatchItem("walk-2", str(captures / "walk"), "patch", "neutral", "1:4"),
        BatchItem("squat", str(tmp_path / "squat"), "patch", "neutral_5k", ""),
    ]
    # the same capture with the same settings twice is one item
    assert len(batch_items([str(captures / "walk")] * 2)) == 1


@pytest.mark.parametrize(
    ("sources", "kwargs", "error", "match"),
    [
        (["nowhere"], {}, MeshmocapFileNotFoundError, "batch: nowhere: no such capture"),
        (["no*where"], {}, MeshmocapFileNotFoundError, "'no\\*where' matches no capture"),
        (["{walk}"], {"method": "fast"}, InputError, "method must be one of .* found 'fast'"),
        (["{walk}"], {"frames": "1:x"}, InputError, "expected START:STOP\\[:STEP\\]"),
        ([], {}, InputError, "expected one or more captures"),
    ],
)
def test_bad_items_are_one_line_errors(captures, sources, kwargs, error, match):
    sources = [s.format(walk=captures / "walk") for s in sources]
    with pytest.raises(error, match=match):
        batch_items(sources, **kwargs)


def test_manifest_without_capture_column_is_refused(tmp_path):
    (tmp_path / "m.csv").write_text("path,method\nx,patch\n")
    with pytest.raises(InputError, match=r"m.csv: a manifest needs a 'capture' column"):
        batch_items([str(tmp_path / "m.csv")])


def test_batch_command_in_process(captures, tmp_path, capsys):
    argv = [
        "batch",
        str(captures / "walk"),
        "--method",
        METHOD,
        "--out",
        str(tmp_path / "b"),
        "--serial",
    ]
    assert main(argv) == 0
    out = capsys.readouterr().out
    assert "batch: 1 of 1 captures tracked one after another" in out
    assert main(["report", str(tmp_path / "b"), "--out", str(tmp_path / "r.html")]) == 0
    html = (tmp_path / "r.html").read_text()
    assert "1 of 1 captures tracked" in html and "joint error per frame" in html
    assert main(["report", str(tmp_path / "b"), "walk", "--out", str(tmp_path / "r.html")]) == 2
    assert "is a batch folder; give no track folders" in capsys.readouterr().err
    assert main(["batch", str(tmp_path / "none"), "--out", str(tmp_path / "c")]) == 2
    assert "meshmocap: error: batch:" in capsys.readouterr().err
    assert (
        main(["batch", str(captures / "walk"), "--out", str(tmp_path / "d"), "--workers", "0"]) == 2
    )
    assert "--workers must be an integer ≥ 1, found 0" in capsys.readouterr().err
