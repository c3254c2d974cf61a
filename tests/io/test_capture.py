"""Capture folders and mesh sequences read as captures (:mod:`meshmocap.io.capture`): the
frames, cameras, masks, hulls and truth a synthetic capture holds read back as written;
hull and truth files round-trip (the hull's mesh losslessly); a frame without hull says
why; a folder of meshes is a sequence capture whose gaps are missing frames."""

import json
import shutil

import numpy as np
import pytest

from meshmocap.errors import FormatError, InputError, MeshmocapFileNotFoundError
from meshmocap.geometry.carving import VoxelHull, hull_mesh
from meshmocap.io.capture import (
    Capture,
    SequenceCapture,
    Truth,
    hull_missing,
    hull_note,
    open_capture,
    read_hull,
    read_hull_mesh,
    read_truth,
    write_hull,
    write_missing_hull,
    write_truth,
)


def test_a_capture_folder_reads_back_its_frames(jump):
    c = Capture(jump.path)
    assert len(c) == 5 and c.indices == [0, 1, 2, 3, 4] and c.fps == 30.0
    assert [cam.name for cam in c.cameras] == ["C1", "C2", "C3", "C4"]
    assert repr(c) == f"Capture({str(jump.path)!r}, 5 frames, 4 cameras)"
    assert c.meta["spec"]["motion"] == "jumping_jacks" and c.notes() == {}
    f = c[-1]
    assert f.index == 4 and f.missing is None
    assert f.truth.vertices.shape == (5000, 3) and f.truth.joints.shape == (15, 3)
    assert f.truth.rotations.shape[1:] == (3, 3) and f.truth.root.shape == (3,)
    assert c.truth_faces.shape[1] == 3 and c.truth_faces.max() == 4999
    masks = f.silhouettes
    assert len(masks) == 4 and all(m.shape == (480, 640) and m.dtype == bool for m in masks)
    assert all(m.any() for m in masks)  # every camera sees the performer
    hull = f.hull
    assert hull.voxel_size == 0.02 and hull.occupancy.any()
    V, F = f.hull_mesh
    assert F.max() < len(V)
    # the hull's surface lies within a voxel of its occupied voxels' box
    lo, hi = hull.origin, hull.origin + hull.voxel_size * (np.array(hull.occupancy.shape) - 1)
    assert (lo - hull.voxel_size <= V).all() and (hi + hull.voxel_size >= V).all()
    with pytest.raises(InputError, match="frame position 5 out of range for 5 frames"):
        c[5]


def test_truth_and_hull_files_round_trip(jump, tmp_path):
    f = Capture(jump.path)[2]
    t = f.truth
    write_truth(tmp_path / "t.npz", t)
    back = read_truth(tmp_path / "t.npz")
    # vertices are stored as float32 (byte-shuffled), the rest as written
    np.testing.assert_array_equal(back.vertices, t.vertices.astype(np.float32))
    for key in ("joints", "rotations", "root"):
        np.testing.assert_array_equal(getattr(back, key), getattr(t, key))
    write_truth(tmp_path / "v.npz", Truth(t.vertices))  # a mesh sequence's: vertices only
    assert read_truth(tmp_path / "v.npz").joints is None

    hull = f.hull
    write_hull(tmp_path / "h.npz", hull, note="carved from 3 of 4 cameras")
    again = read_hull(tmp_path / "h.npz")
    np.testing.assert_array_equal(again.occupancy, hull.occupancy)
    np.testing.assert_array_equal(again.origin, hull.origin)
    V, F = read_hull_mesh(tmp_path / "h.npz")
    V0, F0 = hull_mesh(hull)
    np.testing.assert_array_equal(F, F0)
    # lossless up to the float32 every reader of a hull mesh gets (0.06 µm)
    np.testing.assert_array_equal(V, V0.astype(np.float32))
    assert hull_note(tmp_path / "h.npz") == "carved from 3 of 4 cameras"
    assert hull_missing(tmp_path / "h.npz") is None


def test_a_frame_without_hull_says_why(tmp_path):
    write_missing_hull(tmp_path / "m.npz", "only 1 of 4 cameras see the subject")
    assert hull_missing(tmp_path / "m.npz") == "only 1 of 4 cameras see the subject"
    assert hull_note(tmp_path / "m.npz") == "only 1 of 4 cameras see the subject"
    for read in (read_hull, read_hull_mesh):
        with pytest.raises(FormatError, match="the frame has no hull \\(only 1 of 4"):
            read(tmp_path / "m.npz")
    assert hull_missing(tmp_path / "absent.npz") is None  # reported when it is read
    tiny = VoxelHull(np.ones((2, 2, 2), bool), np.zeros(3), 0.5)
    write_hull(tmp_path / "tiny.npz", tiny)
    assert hull_note(tmp_path / "tiny.npz") == ""  # carved from every camera


def test_a_folder_of_meshes_is_a_sequence_capture(mesh_folder, small_walk, tmp_path):
    seq = open_capture(mesh_folder)
    assert isinstance(seq, SequenceCapture) and len(seq) == 5 and seq.gaps == []
    assert seq.units == "m" and seq.fps == 30.0 and not seq.fps_given
    for f, truth in zip(seq, small_walk, strict=True):
        V, F = f.hull_mesh
        np.testing.assert_allclose(V, truth.truth.vertices, atol=1e-6)  # float32 files
        np.testing.assert_array_equal(F, small_walk.truth_faces)
    mm = SequenceCapture(mesh_folder, scale=0.001, fps=25)
    assert mm.units == "mm" and mm.fps == 25.0 and mm.fps_given
    np.testing.assert_allclose(mm[0].hull_mesh[0], seq[0].hull_mesh[0] * 0.001)
    gap = tmp_path / "gap"
    shutil.copytree(mesh_folder, gap)
    (gap / "00002.ply").unlink()
    g = SequenceCapture(gap)
    assert g.indices == [0, 1, 2, 3, 4] and g.gaps == [2]
    assert g[2].missing == "no file of frame 2 (the files skip from frame 1 to 3)"
    with pytest.raises(InputError, match="fps must be a positive number"):
        SequenceCapture(mesh_folder, fps=0)


def test_folders_that_are_not_captures_are_refused_in_one_line(small_walk, tmp_path):
    with pytest.raises(MeshmocapFileNotFoundError, match="is not a folder"):
        Capture(tmp_path / "absent")
    masks = tmp_path / "masks"
    shutil.copytree(small_walk.path, masks, ignore=shutil.ignore_patterns("hulls", "truth"))
    (masks / "capture.json").unlink()
    with pytest.raises(MeshmocapFileNotFoundError, match="run 'meshmocap hull"):
        open_capture(masks)
    bad = tmp_path / "bad"
    shutil.copytree(small_walk.path, bad)
    meta = json.loads((bad / "capture.json").read_text())
    (bad / "capture.json").write_text(json.dumps({**meta, "frames": ["a"]}))
    with pytest.raises(FormatError, match="'frames' must be a list of frame numbers"):
        Capture(bad)


def test_hull_meshes_read_the_same_whatever_their_integers_width(jump, tmp_path):
    """The compiled unpacking (native integers of up to 4 bytes) and the array one (any
    other) give the same vertices and triangles: stored at every width and byte order, and
    with half-voxel steps too scattered for a table."""
    hull = Capture(jump.path)[2].hull
    write_hull(tmp_path / "h.npz", hull)
    V0, F0 = (a.copy() for a in read_hull_mesh(tmp_path / "h.npz"))
    with np.load(tmp_path / "h.npz") as z:
        stored = dict(z)
    widths = [
        ("<i2", "u1", "<u2"),
        ("<i4", "<u2", "<u4"),
        (">i2", "u1", ">u2"),
        ("<i8", "<u8", "<u8"),
    ]
    for dk, dtop, below in widths:
        d = {**stored, "mesh_dK": stored["mesh_dK"].astype(dk)}
        d.update(
            mesh_dtop=stored["mesh_dtop"].astype(dtop),
            mesh_below=stored["mesh_below"].astype(below),
        )
        np.savez(tmp_path / "w.npz", **d)
        V, F = read_hull_mesh(tmp_path / "w.npz")
        assert V.dtype == np.float64 and F.dtype == np.int64, (dk, dtop, below)
        np.testing.assert_array_equal(V, V0)
        np.testing.assert_array_equal(F, F0)
    K = np.array([[0, 0, 0], [1000, 0, 0], [-1000, 1, 1]])  # x's steps scattered
    d = {**stored, "mesh_dK": K.astype(np.int16), "mesh_dtop": np.array([2], np.uint8)}
    np.savez(tmp_path / "s.npz", **{**d, "mesh_below": np.array([[2, 1, 0]], np.uint8)})
    V, F = read_hull_mesh(tmp_path / "s.npz")
    o, h = stored["origin"], float(stored["voxel_size"])
    expect = (o + np.cumsum(K, axis=0) / 2 * h).astype(np.float32)
    np.testing.assert_array_equal(V, expect)
    np.testing.assert_array_equal(F, [[0, 1, 2]])
