"""Estimate once per capture: the body and the first pose are cached for the capture (in the
user's cache folder, never in the capture), keyed by its content, the options, the code and
(first pose) the template; every track of the capture shares them."""

import shutil
from dataclasses import replace

import numpy as np
import pytest

from meshmocap.apps.demo import drop_hull_meshes
from meshmocap.body.template import load_template
from meshmocap.estimate.performer import capture_cache as cc
from meshmocap.estimate.performer import tracking_template as tt
from meshmocap.estimate.performer.subject import SubjectEstimate
from meshmocap.io.capture import open_capture
from meshmocap.io.results import read_state
from meshmocap.io.start import Start
from meshmocap.trackers import driver
from meshmocap.trackers.options import TrackOptions
from meshmocap.trackers.registry import make_tracker


@pytest.fixture(scope="module")
def walk(synth_capture, tmp_path_factory):
    """A copy of the session's 3-frame walk without its cache (another test may have
    tracked it): these tests fill the cache and count the calls that fill it."""
    copy = tmp_path_factory.mktemp("walk") / "cap"
    ignore = shutil.ignore_patterns(cc.CACHE_FOLDER)
    shutil.copytree(synth_capture("walk", stop=3).path, copy, ignore=ignore)
    return copy


def _counting(calls):
    def estimate(capture, **options):
        calls.append(options)
        t = load_template("neutral_5k")
        R = np.tile(np.eye(3), (1, 31, 1, 1))
        root = t.skeleton.rest_positions[:1]
        return SubjectEstimate(t, "hull", (0,), np.zeros(3), R, root, 0.002, 1.0, {"a": 1.5})

    return estimate


def test_the_digest_follows_the_content_not_the_place_nor_derived_files(walk, tmp_path):
    d = cc.capture_digest(open_capture(walk))
    copy = tmp_path / "copy"
    shutil.copytree(walk, copy)
    assert cc.capture_digest(open_capture(copy)) == d  # a copy: the same content
    drop_hull_meshes(copy)  # hulls rewritten (derived from the silhouettes): no change
    shutil.rmtree(copy / "truth")  # the truth is not read by the estimators
    assert cc.capture_digest(open_capture(copy)) == d
    mask = sorted((copy / "silhouettes").rglob("*.png"))[0]
    mask.write_bytes(mask.read_bytes() + b"\0")  # one mask changes
    assert cc.capture_digest(open_capture(copy)) != d


def test_the_body_is_estimated_once_per_capture_and_options(walk, tmp_path, monkeypatch):
    cap = open_capture(walk)
    calls: list = []
    monkeypatch.setattr(tt, "estimate_subject", _counting(calls))
    a = tt.tracking_template(cap, "auto", tmp_path / "track_a")
    b = tt.tracking_template(cap, "auto", tmp_path / "track_b")  # another track: cached
    assert len(calls) == 1 and (tmp_path / "track_b" / tt.SUBJECT_FILE).is_file()
    np.testing.assert_array_equal(a.template.V, b.template.V)
    # the cached body read back is the estimated one to the bit: the same weights in the
    # same storage order, the same file beside either track
    for part in ("data", "indices", "indptr"):
        assert np.array_equal(getattr(a.template.weights, part), getattr(b.template.weights, part))
    fa, fb = (np.load(tmp_path / f / tt.SUBJECT_FILE) for f in ("track_a", "track_b"))
    assert fa.files == fb.files and all(np.array_equal(fa[k], fb[k]) for k in fa.files)
    est = cc.cached_subject(cap, kind="auto", estimate=_counting(calls))
    assert len(calls) == 1 and est.notes == {"a": 1.5} and est.frames == (0,)
    assert est.rms == 0.002 and est.z.shape == (3,) and est.R.shape == (1, 31, 3, 3)
    cc.cached_subject(cap, kind="hull", estimate=_counting(calls))  # other options
    assert len(calls) == 2
    tt.tracking_template(cap, "auto", tmp_path / "track_c", refresh=True)  # estimate again
    assert len(calls) == 3
    assert not (walk / cc.CACHE_FOLDER).exists()  # never in the capture
    assert len(list(cc.cache_folder(cap).glob("subject-*.npz"))) == 4  # 2 options, each 2 files


def test_the_cache_is_the_users_one_folder_per_capture_and_off_caches_nothing(
    walk, tmp_path, monkeypatch
):
    cap = open_capture(walk)
    monkeypatch.setenv("MESHMOCAP_CACHE", str(tmp_path / "c"))
    folder = cc.cache_folder(cap)
    assert folder.parent == tmp_path / "c" / "captures" and folder.name.startswith("cap-")
    assert cc.cache_folder(open_capture(walk / ".." / "cap")) == folder  # the resolved path
    copy = tmp_path / "cap"
    shutil.copytree(walk, copy)
    assert cc.cache_folder(open_capture(copy)) != folder  # another capture folder
    monkeypatch.delenv("MESHMOCAP_CACHE")
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    assert cc.cache_folder(cap).parent == tmp_path / "xdg" / "meshmocap" / "captures"
    monkeypatch.setenv("MESHMOCAP_CACHE", "off")
    assert cc.cache_folder(cap) is None
    calls: list = []
    for _ in range(2):  # no cache: estimated every time, nothing written
        cc.cached_subject(cap, kind="auto", estimate=_counting(calls))
    assert len(calls) == 2 and not (tmp_path / "xdg").exists()


@pytest.mark.slow
def test_the_first_pose_is_searched_once_for_every_tracker(walk, tmp_path, monkeypatch):
    cap = open_capture(walk)
    found = []
    search = driver._search_first_pose

    def counting(template, frame, options=None):
        found.append(frame.index)
        return search(template, frame, options)

    monkeypatch.setattr(driver, "_search_first_pose", counting)
    t = load_template("neutral_5k")
    tracks = [
        driver.track_sequence(
            make_tracker(method, template=t),
            t,
            cap,
            tmp_path / method,
            TrackOptions(show_progress=False, frames=slice(0, 2)),  # the start is frame 0's
        )
        for method in ("articulated_icp", "patch")
    ]
    assert found == [0]  # searched for the first tracker, read back for the second
    assert tracks[0].messages[0] == tracks[1].messages[0]
    assert tracks[0].messages[0].startswith("init auto: ")
    first = [read_state(tmp_path / m, 0)["pose_R"] for m in ("articulated_icp", "patch")]
    np.testing.assert_array_equal(*first)  # the very same pose
    assert tracks[0].start.source == "search" and tracks[0].start.label in tracks[0].messages[0]


def test_a_start_is_cached_with_the_capture_bit_for_bit(walk):
    cap = open_capture(walk)
    rng = np.random.default_rng(5)
    s = Start(0, rng.normal(size=(31, 3, 3)), rng.normal(size=3), "search", False, "x@0°")
    s = replace(s, score=0.01234567890123, key=0.02, runner_up="y@90°", runner_up_key=0.021)
    found = []
    t = load_template("neutral")  # a template no other test searches with

    def find():
        found.append(1)
        return s

    first = cc.cached_first_pose(cap, t, 0, find, options={"seed": 123})
    again = cc.cached_first_pose(cap, t, 0, find, options={"seed": 123})
    assert first is s and len(found) == 1  # found once, then read from the cache
    assert again.R.tobytes() == s.R.tobytes() and again.root.tobytes() == s.root.tobytes()
    assert (again.score, again.runner_up, again.margin) == (s.score, s.runner_up, s.margin)
    assert not again.confident and again.label == "x@0°"
    cc.cached_first_pose(cap, t, 0, find, options={"seed": 124})  # other options: searched
    assert len(found) == 2
