"""The demo keeps what a user needs: hull meshes are rebuilt from their voxel occupancy, and
finished tracks lose only the state that resumes an interrupted run."""

import json
from pathlib import Path

import numpy as np

from meshmocap.apps.demo import DEMO_METHODS, drop_hull_meshes, drop_resume_state
from meshmocap.io.capture import Capture
from meshmocap.io.results import FrameResult, read_state, read_track, start_track, write_frame
from meshmocap.studio.synth import SynthSpec, synthesize


def test_hull_meshes_are_rebuilt_from_the_voxels(tmp_path):
    cap = synthesize(
        tmp_path / "cap",
        SynthSpec(motion="walk", template="neutral_5k", stop=2),
        show_progress=False,
    )
    before = [cap[k].hull_mesh for k in range(2)]
    size = sum(p.stat().st_size for p in (cap.path / "hulls").iterdir())
    assert drop_hull_meshes(cap.path) == 2
    left = sum(p.stat().st_size for p in (cap.path / "hulls").iterdir())
    assert left < 0.15 * size  # the meshes are most of the hulls' bytes
    again = Capture(cap.path)
    for k, (V, F) in enumerate(before):
        V2, F2 = again[k].hull_mesh
        assert np.array_equal(F2, F) and np.array_equal(V2, V)  # the same mesh, bit for bit
        assert again[k].hull.occupancy.any()
    assert drop_hull_meshes(cap.path) == 0


def test_resume_state_is_dropped_but_the_last(tmp_path):
    meta = {"method": "toy", "template": "toy", "eval_names": ["a"], "eval_parents": [-1]}
    start_track(tmp_path, meta, np.zeros((1, 3), np.int64), resume=False)
    rng = np.random.default_rng(0)
    for i in range(4):
        state = {"R": rng.normal(size=(50, 3, 3)), "c": rng.normal(size=(50, 3))}
        write_frame(
            tmp_path,
            FrameResult(
                i,
                rng.normal(size=(1, 3)),
                rng.normal(size=(9, 3)),
                energies={"data": 1.0 + i},
                state=state,
            ),
        )
    before = read_track(tmp_path)
    assert drop_resume_state(tmp_path) == 3
    after = read_track(tmp_path)
    for k in ("joints", "vertices", "frames", "healthy"):
        assert np.array_equal(getattr(after, k), getattr(before, k))
    assert after.energies["data"].tolist() == [1.0, 2.0, 3.0, 4.0]
    assert read_state(tmp_path, 2) == {} and set(read_state(tmp_path, 3)) == {"R", "c"}
    assert drop_resume_state(tmp_path) == 0


def test_files_the_tracks_share_are_stored_once(tmp_path):
    """Equal files become hard links to the first (its bytes stored once, each folder still
    holding its own readable file); a different file is left alone; a rewrite of one
    (atomic: a new file) leaves the others as they were."""
    import os

    from meshmocap._atomic import write_bytes_atomic
    from meshmocap.apps.demo import link_duplicates

    a, b, c, d = (tmp_path / n / "subject.npz" for n in "abcd")
    for p, data in ((a, b"body" * 100), (b, b"body" * 100), (c, b"body" * 100), (d, b"other")):
        p.parent.mkdir()
        p.write_bytes(data)
    assert link_duplicates([a, b, c, d, tmp_path / "absent.npz"]) == 800
    assert os.path.samefile(a, b) and os.path.samefile(a, c) and not os.path.samefile(a, d)
    assert b.read_bytes() == b"body" * 100 and d.read_bytes() == b"other"
    assert link_duplicates([a, b, c, d]) == 0  # linked already
    write_bytes_atomic(b, b"new body")
    assert a.read_bytes() == c.read_bytes() == b"body" * 100 and b.read_bytes() == b"new body"


def test_the_demo_guard_has_a_record_of_every_demo_tracker():
    """``benchmarks/bench_demo_guard.py`` fails a change that makes a tracker worse on the
    demo than its record: the record is in the repository, one entry per demo tracker."""
    path = Path(__file__).parents[2] / "benchmarks" / "demo_guard.json"
    record = json.loads(path.read_text())
    assert set(record["methods"]) == set(DEMO_METHODS)
    for figures in record["methods"].values():
        assert 0 < figures["mean_mm"] <= figures["worst_frame_mm"]
        assert figures["seconds_per_frame"] > 0
