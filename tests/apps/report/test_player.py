"""The report's 3D player shows every frame of a track and says what it shows."""

import json

import numpy as np
import pytest

from external import walk_track
from meshmocap.apps.report.player import (
    MIN_HULL_POINTS,
    decode_array,
    player_from_tracks,
    player_payload,
    track_templates,
)
from meshmocap.body.template import load_template, save_template
from meshmocap.io.capture import Capture, Truth, write_meta, write_truth
from meshmocap.io.results import read_track

T = 150  # past the 120 frames the player used to stop at


@pytest.fixture(scope="module")
def long_track(tmp_path_factory):
    """A 150-frame walk as a track whose body is an estimated one (its file in the track
    folder, as `meshmocap track` keeps it), and a capture of its truth."""
    root = tmp_path_factory.mktemp("player")
    posed = walk_track(root / "track", T, 30.0)
    meta_file = root / "track" / "track.json"
    meta = json.loads(meta_file.read_text())
    meta.update(template="subject", template_source="estimated", template_file="subject.npz")
    meta_file.write_text(json.dumps(meta))
    body = load_template("neutral_5k")
    save_template(root / "track" / "subject.npz", body)
    (root / "cap" / "truth").mkdir(parents=True)
    write_meta(root / "cap" / "capture.json", {"fps": 30.0})
    for k in range(T):
        write_truth(
            root / "cap" / "truth" / f"{k:05d}.npz", Truth(posed.V[k], posed.eval_joints[k])
        )
    return root / "track", Capture(root / "cap")


def _glb_json(glb: bytes) -> dict:
    length = int.from_bytes(glb[12:16], "little")
    return json.loads(glb[20 : 20 + length])


@pytest.mark.slow
def test_every_frame_of_the_track(long_track):
    folder, cap = long_track
    track = read_track(folder)
    templates = track_templates([folder])
    assert templates[0] is not None and templates[0].n_vertices == 5000
    p = player_from_tracks(cap, [track], templates=templates)
    assert len(p.frames) == len(track.frames) == T and p.n_tracked == T
    assert p.fps == 30.0 and p.note.startswith(f"all {T} tracked frames")
    d = player_payload(p)
    assert len(d["frames"]) == T and d["note"] == p.note
    assert decode_array(d["tracks"][0]["joints"]).shape == (T, 15, 3)
    assert len(decode_array(d["truth"]["joints"])) == T
    # the estimated body is skinned and animated, one key per frame, not morph targets
    g = _glb_json(p.tracks[0].glb)
    assert "skins" in g and g["accessors"][g["animations"][0]["samplers"][0]["input"]]["count"] == T
    assert len(json.dumps(d)) < 10e6


def test_without_its_template_file_the_meshes_play(long_track):
    """A track whose body cannot be had plays its tracked meshes (morph targets): heavier,
    so the hull is thinned, then frames are dropped, and the note says so."""
    folder, cap = long_track
    track = read_track(folder)
    p = player_from_tracks(cap, [track], max_megabytes=4.0)  # no templates: not found
    assert "skins" not in _glb_json(p.tracks[0].glb)
    assert len(p.frames) < T and len(np.unique(np.diff(p.frames))) == 1
    assert "of 150 tracked frames (size budget" in p.note
    capped = player_from_tracks(cap, [track], max_frames=50)
    assert capped.frames.tolist() == list(range(0, T, 3)) and capped.fps == 10.0
    assert capped.note.startswith("every 3rd of 150 tracked frames (--max-frames")


def test_hull_points_thin_before_frames_drop(synth_capture, tmp_path):
    """The hull layer gives way first: each frame keeps at least MIN_HULL_POINTS."""
    cap = synth_capture("walk", stop=4)
    folder = tmp_path / "t"
    walk_track(folder, 4, cap.fps)
    track = read_track(folder)
    full = player_from_tracks(cap, [track])
    assert len(full.frames) == 4 and max(len(h) for h in full.hull) == 1500
    thin = player_from_tracks(cap, [track], max_megabytes=0.03)
    assert len(thin.frames) == 4 and MIN_HULL_POINTS <= max(len(h) for h in thin.hull) < 1500
    assert "hull: up to" in thin.note
    np.testing.assert_array_equal(thin.tracks[0].joints, full.tracks[0].joints)
