"""Synthetic captures end to end: synth → capture folder → hulls → loading, resuming, errors."""

import json
import shutil

import numpy as np
import pytest

from meshmocap.body.template import load_template
from meshmocap.errors import FormatError, InputError, MeshmocapFileNotFoundError
from meshmocap.geometry.carving import distance_grid, hull_mesh
from meshmocap.geometry.mesh import signed_volume
from meshmocap.io.capture import Capture, read_hull, read_hull_mesh, write_hull
from meshmocap.io.meshes import read_mesh
from meshmocap.studio.hulls import compute_hulls
from meshmocap.studio.synth import SynthSpec, synthesize, synthesize_from_meshes


@pytest.fixture(scope="module")
def walk_capture(synth_capture):
    return synth_capture("walk", stop=6)


def test_capture_layout_and_truth(walk_capture):
    cap = walk_capture
    assert len(cap) == 6 and [c.name for c in cap.cameras] == ["C1", "C2", "C3", "C4"]
    assert cap.fps == 60.0 and cap.meta["spec"]["motion"] == "walk"
    f = cap[2]
    assert f.truth.joints.shape == (15, 3) and f.truth.vertices.shape == (5000, 3)
    assert len(f.silhouettes) == 4 and f.silhouettes[0].shape == (480, 640)
    # the hull contains the true surface: ≥ 99 % of the true vertices lie inside the hull or
    # within one voxel of it (the acceptance criterion), by its signed distance
    dist = distance_grid(f.hull)(f.truth.vertices)
    assert np.mean(dist <= f.hull.voxel_size) >= 0.99
    V, _ = f.hull_mesh  # the stored mesh is the hull's surface, within a voxel of the field
    assert np.abs(distance_grid(f.hull)(V)).max() < f.hull.voxel_size


def test_truth_is_the_posed_template(walk_capture):
    t = load_template("neutral_5k")
    f = walk_capture[0]
    posed = t.pose(f.truth.rotations, f.truth.root)
    assert np.allclose(posed.V, f.truth.vertices, atol=1e-6)  # stored as float32
    assert np.allclose(posed.eval_joints, f.truth.joints, atol=1e-12)


def test_hull_occupancy_round_trip(walk_capture, tmp_path):
    h = walk_capture[1].hull
    write_hull(tmp_path / "h.npz", h)
    g = read_hull(tmp_path / "h.npz")
    assert np.array_equal(g.occupancy, h.occupancy) and np.allclose(g.origin, h.origin)


def test_hull_mesh_round_trip_is_exact(walk_capture, tmp_path):
    """The stored mesh reads back as the hull's surface in float32, bit for bit, whether the
    vertex coordinates go through the per-axis table or (far apart) are computed one by one."""
    h = walk_capture[1].hull
    V, F = hull_mesh(h)
    K = np.rint((V - h.origin) / h.voxel_size * 2)  # half-voxel grid steps
    for k, spread in enumerate((0, 10 * len(V))):  # the second spreads one axis far apart
        K2 = K.copy()
        K2[: len(V) // 2, 0] += spread
        V2 = h.origin + K2 / 2 * h.voxel_size
        write_hull(tmp_path / f"{k}.npz", h, mesh=(V2, F))
        with np.load(tmp_path / f"{k}.npz") as z:
            assert "mesh_dK" in z.files  # stored on the grid
        W, G = read_hull_mesh(tmp_path / f"{k}.npz")
        assert np.array_equal(W, V2.astype(np.float32)) and np.array_equal(G, F)
        assert W.dtype == np.float64 and G.dtype == np.int64


def test_interrupted_synth_resumes_and_keeps_finished_frames(walk_capture, tmp_path):
    out = tmp_path / "cap"
    shutil.copytree(walk_capture.path, out)
    done = out / "truth" / "00001.npz"
    before = done.stat().st_mtime_ns
    (out / "truth" / "00004.npz").unlink()  # as if the run stopped during frame 4
    (out / "truth" / "00005.npz").unlink()
    cap = synthesize(
        out, SynthSpec(motion="walk", template="neutral_5k", stop=6), show_progress=False
    )
    assert len(cap) == 6 and (out / "truth" / "00005.npz").is_file()
    assert done.stat().st_mtime_ns == before  # finished frames were not rewritten
    with pytest.raises(InputError, match="other parameters"):
        synthesize(out, SynthSpec(motion="squat", template="neutral_5k", stop=6))


def test_hull_command_recomputes_from_silhouettes(walk_capture, tmp_path):
    out = tmp_path / "real"
    shutil.copytree(
        walk_capture.path, out, ignore=shutil.ignore_patterns("truth", "hulls", "capture.json")
    )
    run = compute_hulls(out, show_progress=False)
    cap = run.capture
    assert len(cap) == 6 and run.carved == 6 and not run.partial and not run.missing
    assert np.array_equal(cap[3].hull.occupancy, walk_capture[3].hull.occupancy)  # deterministic
    V, F = cap[3].hull_mesh
    V0, F0 = walk_capture[3].hull_mesh
    assert np.array_equal(V, V0) and np.array_equal(F, F0)


def test_hull_input_errors(walk_capture, tmp_path):
    out = tmp_path / "bad"
    shutil.copytree(
        walk_capture.path, out, ignore=shutil.ignore_patterns("truth", "hulls", "capture.json")
    )
    (out / "silhouettes" / "C9").mkdir()
    with pytest.raises(InputError, match=r"holds 5 camera folders but the camera file lists 4"):
        compute_hulls(out)
    (out / "silhouettes" / "C9").rmdir()
    shutil.rmtree(out / "silhouettes" / "C3")
    with pytest.raises(MeshmocapFileNotFoundError, match="camera 'C3' has no silhouette folder"):
        compute_hulls(out)
    (out / "cameras.json").unlink()
    with pytest.raises(MeshmocapFileNotFoundError, match=r"no cameras\.json"):
        compute_hulls(out)


def test_a_dropped_camera_frame_is_carved_from_the_others(walk_capture, tmp_path):
    from meshmocap.errors import MissingFrameWarning
    from meshmocap.io.silhouettes import write_mask

    out = tmp_path / "empty"
    shutil.copytree(
        walk_capture.path, out, ignore=shutil.ignore_patterns("truth", "hulls", "capture.json")
    )
    write_mask(out / "silhouettes" / "C2" / "00000.png", np.zeros((480, 640), bool))
    (out / "silhouettes" / "C3" / "00002.png").unlink()
    for cam in ("C1", "C2", "C4"):  # frame 4: only C3 sees the subject
        write_mask(out / "silhouettes" / cam / "00004.png", np.zeros((480, 640), bool))
    with pytest.warns(MissingFrameWarning, match="1 frame without hull") as info:
        run = compute_hulls(out)
    assert "\n" not in str(info[0].message)
    assert run.partial == {
        0: "carved from 3 of 4 cameras (C2: empty mask)",
        2: "carved from 3 of 4 cameras (C3: no silhouette file)",
    }
    assert run.missing == {
        4: "only 1 of 4 cameras see the subject (C1: empty mask, C2: empty "
        "mask, C4: empty mask); at least 2 needed"
    }
    cap = run.capture
    assert len(cap) == 6 and cap[4].missing and cap[0].missing is None
    assert cap.notes() == {**run.partial, **run.missing}
    # three cameras carve a larger hull than four, never a smaller one
    assert np.count_nonzero(cap[0].hull.occupancy) >= np.count_nonzero(
        walk_capture[0].hull.occupancy
    )


def test_capture_loading_errors(tmp_path):
    with pytest.raises(MeshmocapFileNotFoundError, match="not a folder"):
        Capture(tmp_path / "missing")
    (tmp_path / "capture.json").write_text(json.dumps({"format": "other"}))
    with pytest.raises(FormatError, match="expected format"):
        Capture(tmp_path)


@pytest.mark.slow
def test_thirty_frame_cmu_walk_end_to_end(cmu, tmp_path):
    cap = synthesize(
        tmp_path / "cap", SynthSpec(motion=str(cmu / "35_01.amc"), stop=30), show_progress=False
    )
    assert len(cap) == 30
    low = min(f.truth.vertices[:, 2].min() for f in cap)
    assert abs(low) < 0.03  # the retargeted subject walks on the floor
    vols = [f.hull.volume for f in cap]
    assert min(vols) > 0.06  # m³: a human body (~0.065 m³) plus phantom volume


def test_crane_hulls_contain_the_real_surface(shared_data, tmp_path):
    """Real data: MIT crane frames rendered from ring8 and carved at 1 cm; the hull holds the
    true surface (≥ 99 % of vertices inside or within a voxel) with phantom volume, more of
    it from the sparse humaneva4 rig."""
    src = shared_data / "meshes" / "crane" / "first10"
    ratios = {}
    for rig in ("ring8", "humaneva4"):
        cap = synthesize_from_meshes(
            src, tmp_path / rig, rig=rig, frames=range(0, 10, 4), show_progress=False
        )
        ratios[rig] = []
        for f in cap:
            V = f.truth.vertices
            assert np.mean(distance_grid(f.hull)(V) <= f.hull.voxel_size) >= 0.99
            F = read_mesh(src / "mesh_0000.obj")[1]
            ratios[rig].append(f.hull.volume / signed_volume(V, F))
    assert 1.0 < np.mean(ratios["ring8"]) < np.mean(ratios["humaneva4"])


def test_any_mesh_folder_opens_as_a_capture(tmp_path, walk_capture):
    import trimesh

    from meshmocap.io.capture import SequenceCapture, open_capture

    for i in (2, 10, 1):
        trimesh.creation.icosphere(radius=0.1 * i).export(tmp_path / f"frame_{i}.ply")
    cap = open_capture(tmp_path)
    # numbered by their names: frames 3 to 9 have no file (missing, kept in the numbering)
    assert isinstance(cap, SequenceCapture) and cap.indices == list(range(1, 11))
    assert cap.gaps == list(range(3, 10)) and "skip from frame 2 to 10" in cap[2].missing
    radii = [np.linalg.norm(f.hull_mesh[0], axis=1).mean() for f in cap if not f.missing]
    assert np.allclose(radii, [0.1, 0.2, 1.0], rtol=1e-3)  # natural order: 1, 2, 10
    assert isinstance(open_capture(walk_capture.path), Capture)
