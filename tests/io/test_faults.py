"""Faults a studio meets, with their exact outcomes: a dropped frame is carved from the
cameras that see the subject or recorded as missing; tracking coasts across a missing frame
and flags it; an unreadable frame of a mesh sequence is skipped, not fatal; a second run
into the same folder is refused, and a killed run leaves no stuck lock; reruns say what was
resumed; long runs log to a pipe; hulls are stored compactly and old captures still read."""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from meshmocap.cli import main
from meshmocap.errors import FolderBusyError
from meshmocap.io.capture import Capture, read_hull_mesh
from meshmocap.io.results import read_track
from meshmocap.io.silhouettes import write_mask

ICP = ["--method", "articulated_icp", "--max-iter", "2", "--template", "neutral_5k"]


@pytest.fixture(autouse=True)
def _quiet_progress(monkeypatch):
    """No progress or phase lines on stderr, however slow a loaded machine runs: the
    messages checked here are exact."""
    monkeypatch.setenv("MESHMOCAP_PROGRESS_SECONDS", "3600")
    monkeypatch.setattr("meshmocap._progress.PHASE_SECONDS", 3600.0)


@pytest.fixture(scope="module")
def cap(small_walk) -> Path:
    """A 5-frame synthetic capture (neutral_5k walk at 30 fps, 2 cm voxels), the session's."""
    return small_walk.path


def _real(cap: Path, tmp: Path) -> Path:
    """The capture as a studio delivers it: cameras and silhouettes only."""
    out = tmp / "real"
    shutil.copytree(cap, out, ignore=shutil.ignore_patterns("hulls", "truth", "capture.json"))
    return out


@pytest.mark.slow
def test_a_dropped_frame_is_carved_from_the_others_and_tracked_through(cap, tmp_path, capsys):
    real = _real(cap, tmp_path)
    empty = np.zeros((480, 640), bool)
    write_mask(real / "silhouettes" / "C1" / "00001.png", empty)  # C1 lost the subject
    for cam in ("C1", "C2", "C3"):  # frame 3 dropped: only C4 has a mask
        write_mask(real / "silhouettes" / cam / "00003.png", empty)
    assert main(["hull", str(real)]) == 0
    out, err = capsys.readouterr()
    assert "hulls of 5 frames" in out
    assert err == (
        "meshmocap: warning: 1 frame without hull (trackers coast across them), "
        "first 00003: only 1 of 4 cameras see the subject (C1: empty mask, C2: empty "
        "mask, C3: empty mask); at least 2 needed; 1 frame carved from fewer "
        "cameras, first 00001: carved from 3 of 4 cameras (C1: empty mask)\n"
    )
    c = Capture(real)
    assert c.notes() == {
        1: "carved from 3 of 4 cameras (C1: empty mask)",
        3: "only 1 of 4 cameras see the subject (C1: empty mask, C2: empty "
        "mask, C3: empty mask); at least 2 needed",
    }
    assert main(["track", str(real), *ICP, "--out", str(tmp_path / "t")]) == 0
    out, err = capsys.readouterr()
    assert (
        "tracked 5 frames with articulated_icp" in out and "1 flagged unhealthy (1 missing)" in out
    )
    warned = [x for x in err.splitlines() if x.startswith("meshmocap: warning:")]
    assert warned[0] == (  # a progress line may come first on a loaded machine
        "meshmocap: warning: track: 1 of 5 frames were carved from fewer than the 4 cameras "
        "(first 1: carved from 3 of 4 cameras (C1: empty mask)); their hulls are coarser, and "
        "their silhouettes are scored only in the cameras that saw the subject"
    )
    assert warned[1].startswith(
        "meshmocap: warning: 1 frame without a usable observation (skipped, coasted "
        "across), first 3: only 1 of 4 cameras"
    )
    t = read_track(tmp_path / "t")
    # frame 4, two frames after the last fit, may find a limb lost and re-initialise it
    assert t.flags[:4] == ((), (), (), ("missing",)) and "missing" not in t.flags[4]
    assert t.messages[3] == c.notes()[3] and not t.healthy[3] and t.healthy[4]
    assert np.array_equal(t.vertices[3], t.vertices[2])  # coasted: the last state, kept
    assert not np.array_equal(t.vertices[4], t.vertices[3])  # the next real frame is fitted
    assert np.isfinite(t.joints).all()


@pytest.mark.slow
def test_a_missing_hull_file_is_a_missing_frame(cap, tmp_path):
    from meshmocap.body.template import load_template
    from meshmocap.trackers.driver import track_sequence
    from meshmocap.trackers.options import TrackOptions
    from meshmocap.trackers.registry import make_tracker

    c = tmp_path / "c"
    shutil.copytree(cap, c)
    (c / "hulls" / "00002.npz").unlink()  # an old run died before this hull was written
    t = track_sequence(
        make_tracker("articulated_icp", max_iter=2),
        load_template("neutral_5k"),
        Capture(c),
        tmp_path / "t",
        TrackOptions(show_progress=False),
    )
    assert t.flags[2] == ("missing",) and "missing" not in t.flags[3]  # 3 may be re-seated
    assert not t.messages[2].startswith("Meshmocap")  # the reason in words, no class name
    assert "hulls/00002.npz" in t.messages[2]


@pytest.mark.slow
def test_an_unreadable_frame_of_a_mesh_sequence_is_skipped(cap, tmp_path, capsys):
    from meshmocap.io.meshes import write_mesh

    seq = tmp_path / "seq"
    seq.mkdir()
    for f in Capture(cap):
        write_mesh(seq / f"mesh_{f.index}.ply", *f.hull_mesh)
    (seq / "mesh_0.ply").write_bytes(b"ply\nformat ascii 1.0\nend_header\n")  # no vertices
    (seq / "mesh_2.ply").write_bytes(b"ply\x00\x00garbage")
    assert (
        main(["track", *map(str, sorted(seq.glob("*.ply"))), *ICP, "--out", str(tmp_path / "t")])
        == 0
    )
    t = read_track(tmp_path / "t")
    assert ["missing" in f for f in t.flags] == [True, False, True, False, False]
    assert "mesh_0.ply" in t.messages[0] and "mesh_2.ply" in t.messages[2]
    assert np.array_equal(t.vertices[0], t.vertices[1])  # before the first readable frame
    assert "2 flagged unhealthy (2 missing)" in capsys.readouterr().out
    for p in seq.glob("*.ply"):
        p.write_bytes(b"not a mesh")
    assert main(["track", str(seq), *ICP, "--out", str(tmp_path / "t2")]) == 2
    assert "track: no frame of" in capsys.readouterr().err


def test_synth_keeps_frames_when_the_subject_leaves_a_camera(tmp_path, capsys):
    from meshmocap.geometry.camera import Camera
    from meshmocap.io.cameras import write_cameras
    from meshmocap.studio.rigs import camera_rig

    cams = camera_rig("humaneva4")
    c = cams[0]  # a camera looking 3 m to the side of the studio: it never sees the walk
    away = Camera(c.K, c.R, c.t + np.array([30.0, 0.0, 0.0]), c.width, c.height, c.dist, "C1")
    write_cameras(tmp_path / "rig.json", [away, *cams[1:]])
    argv = [
        "synth",
        str(tmp_path / "s"),
        "--template",
        "neutral_5k",
        "--fps",
        "30",
        "--frames",
        "0:2",
        "--voxel-size",
        "0.02",
        "--rig",
        str(tmp_path / "rig.json"),
    ]
    assert main(argv) == 0
    out, err = capsys.readouterr()
    assert "wrote" in out and "2 frames" in out
    assert (
        "meshmocap: warning: synth: 2 frames carved from fewer cameras, first 00000: "
        "carved from 3 of 4 cameras (C1: empty mask)" in err
    )


@pytest.mark.slow
def test_a_motion_asked_for_more_frames_than_it_has_says_so(tmp_path, capsys):
    argv = [
        "synth",
        str(tmp_path / "s"),
        "--motion",
        "jumping_jacks",
        "--template",
        "neutral_5k",
        "--fps",
        "5",
        "--frames",
        "18:1500",
        "--voxel-size",
        "0.03",
    ]
    assert main(argv) == 0
    out, err = capsys.readouterr()
    n = len(Capture(tmp_path / "s"))
    assert f"wrote {tmp_path / 's'}: {n} frames" in out and 0 < n < 10
    assert (
        f"meshmocap: warning: synth: frames 18:1500 asked, but jumping_jacks has {18 + n} "
        f"frames at 5 fps: writing {n}"
    ) in err
    assert (
        main(["track", str(tmp_path / "s"), *ICP, "--frames", "0:50", "--out", str(tmp_path / "t")])
        == 0
    )
    assert (
        f"--frames 0:50 asks for frames up to 49; the capture ends at frame {17 + n}: "
        f"tracking {n}" in capsys.readouterr().err
    )


def test_grey_masks_are_thresholded_with_one_warning(cap, tmp_path, capsys):
    from PIL import Image

    real = _real(cap, tmp_path)
    for p in (real / "silhouettes" / "C2").glob("*.png"):  # anti-aliased edges, as JPEG-ish
        m = np.asarray(Image.open(p), dtype=np.float64)
        Image.fromarray((0.9 * m + 10).astype(np.uint8), "L").save(p)
    assert main(["hull", str(real), "--voxel-size", "0.02"]) == 0
    err = capsys.readouterr().err
    assert err == (
        f"meshmocap: warning: hull: 5 masks in {real / 'silhouettes'} are not binary "
        "(grey levels); thresholded at 50 % of full scale\n"
    )
    assert np.array_equal(Capture(real)[2].hull.occupancy, Capture(cap)[2].hull.occupancy)


@pytest.mark.slow
def test_a_rerun_says_what_was_resumed(cap, tmp_path, capsys):
    argv = ["track", str(cap), *ICP, "--out", str(tmp_path / "t")]
    assert main([*argv, "--frames", "0:3"]) == 0
    assert "tracked 3 frames with articulated_icp" in capsys.readouterr().out
    shutil.rmtree(tmp_path / "t")
    assert main(argv) == 0
    (tmp_path / "t" / "frames" / "00004.npz").unlink()  # as if killed before the last frame
    capsys.readouterr()
    assert main(argv) == 0
    assert "tracked 1 frame (4 resumed from an earlier run)" in capsys.readouterr().out
    assert main(argv) == 0
    assert "tracked 0 frames (5 resumed from an earlier run)" in capsys.readouterr().out


_HOLD = """
import sys, time
from meshmocap._atomic import folder_lock
with folder_lock(sys.argv[1], "track"):
    print("locked", flush=True)
    time.sleep(60)
"""


def test_one_writer_per_folder_and_a_killed_run_leaves_no_stuck_lock(tmp_path):
    from meshmocap._atomic import folder_lock

    holder = subprocess.Popen(
        [sys.executable, "-c", _HOLD, str(tmp_path)], stdout=subprocess.PIPE, text=True
    )
    try:
        assert holder.stdout.readline().strip() == "locked"
        with (
            pytest.raises(
                FolderBusyError, match=f"another meshmocap process \\(pid {holder.pid}\\)"
            ),
            folder_lock(tmp_path, "track"),
        ):
            pass
    finally:
        holder.send_signal(signal.SIGKILL)  # kill -9: no clean-up runs in the holder
        holder.wait(10)
        holder.stdout.close()
    with folder_lock(tmp_path, "track"):  # the kernel released it with the process
        assert (tmp_path / ".meshmocap.lock").read_text().strip() == str(os.getpid())
    assert not (tmp_path / ".meshmocap.lock").exists()  # a clean exit leaves no lock file


def test_a_lock_file_removed_as_it_was_opened_is_not_taken(tmp_path, monkeypatch):
    """The last writer removes its lock file between another's open and lock: the other
    then holds a file no name points to, so it opens the folder's lock file again."""
    import fcntl

    from meshmocap._atomic import folder_lock

    real, calls = fcntl.flock, []

    def flock(fd, op):
        calls.append(os.fstat(fd).st_ino)
        if len(calls) == 1:  # the holder finishes now and removes the file
            (tmp_path / ".meshmocap.lock").unlink()
        return real(fd, op)

    monkeypatch.setattr(fcntl, "flock", flock)
    with folder_lock(tmp_path, "track"):
        held = (tmp_path / ".meshmocap.lock").stat().st_ino
        assert len(calls) == 2 and calls[1] == held  # the second try locks the named file
    assert not (tmp_path / ".meshmocap.lock").exists()


def test_long_runs_log_progress_lines_when_stderr_is_not_a_terminal(monkeypatch, capsys):
    from meshmocap._progress import progress

    monkeypatch.setenv("MESHMOCAP_PROGRESS_SECONDS", "0")
    assert list(progress(range(3), label="track")) == [0, 1, 2]
    lines = capsys.readouterr().err.splitlines()
    assert len(lines) == 3 and lines[0].startswith("track: 1/3 (33 %), ")
    assert lines[2].startswith("track: 3/3 (100 %)") and lines[2].endswith("left")
    monkeypatch.setenv("MESHMOCAP_PROGRESS_SECONDS", "3600")
    assert list(progress(range(3), label="track")) == [0, 1, 2]
    assert capsys.readouterr().err == ""  # a short run stays quiet


@pytest.mark.slow
def test_eval_takes_a_mesh_folder_that_track_accepts(cap, tmp_path, capsys):
    from meshmocap.io.meshes import write_mesh

    seq = tmp_path / "seq"
    seq.mkdir()
    for f in Capture(cap):
        write_mesh(seq / f"mesh_{f.index}.obj", *f.hull_mesh)
    assert main(["track", str(seq), *ICP, "--frames", "0:2", "--out", str(tmp_path / "t")]) == 0
    assert main(["eval", str(seq), str(tmp_path / "t"), "--surface-frames", "2"]) == 0
    out = capsys.readouterr().out
    assert "Surface distance to the input meshes" in out and "nan" not in out.lower()


@pytest.mark.slow
def test_point_clouds_without_normals_are_tracked_by_the_patch_tracker(cap, tmp_path, capsys):
    import trimesh

    seq = tmp_path / "pc"
    seq.mkdir()
    for f in Capture(cap):  # PLY point clouds: vertices, no faces, no normals
        (seq / f"{f.index:03d}.ply").write_bytes(
            trimesh.PointCloud(f.hull_mesh[0][::2]).export(file_type="ply")
        )
    argv = [
        "track",
        str(seq),
        "--frames",
        "0:2",
        "--max-iter",
        "2",
        "--n-patches",
        "40",
        "--template",
        "neutral_5k",
    ]
    assert main([*argv, "--out", str(tmp_path / "t")]) == 0
    t = read_track(tmp_path / "t")
    assert np.isfinite(t.vertices).all() and t.healthy.all()


def test_point_normals_point_outwards_on_a_sphere():
    from meshmocap.geometry.normals import point_normals

    rng = np.random.default_rng(0)
    P = rng.normal(size=(3000, 3))
    P /= np.linalg.norm(P, axis=1, keepdims=True)
    N = point_normals(0.5 * P + [1.0, 2.0, 0.3])
    cos = np.einsum("ij,ij->i", N, P)
    assert np.all(cos > 0.95)  # every normal outward, within 18° of the radius


def test_hull_storage_is_compact_lossless_and_old_captures_read_unchanged(cap, tmp_path):
    from meshmocap.geometry.carving import hull_mesh
    from meshmocap.io.meshes import write_mesh

    npz = cap / "hulls" / "00002.npz"
    hull = Capture(cap)[2].hull
    V0, F0 = hull_mesh(hull)
    V, F = read_hull_mesh(npz)
    assert np.array_equal(F, F0) and np.array_equal(V, V0.astype(np.float32).astype(np.float64))
    old = tmp_path / "old"  # a capture written the old way: PLY beside an occupancy-only npz
    shutil.copytree(cap, old)
    for p in (old / "hulls").glob("*.npz"):
        with np.load(p) as z:
            np.savez_compressed(p, **{k: z[k] for k in ("bits", "shape", "origin", "voxel_size")})
        write_mesh(p.with_suffix(".ply"), *hull_mesh(Capture(cap)[int(p.stem)].hull))
    Vo, Fo = Capture(old)[2].hull_mesh
    assert np.array_equal(Vo, V) and np.array_equal(Fo, F)
    with np.load(old / "hulls" / "00002.npz") as z:
        assert "mesh_dK" not in z.files  # it was read from the PLY
    old_bytes = (old / "hulls" / "00002.ply").stat().st_size + (
        old / "hulls" / "00002.npz"
    ).stat().st_size
    assert npz.stat().st_size * 4 <= old_bytes
    from meshmocap.io.capture import write_hull

    write_hull(old / "hulls" / "00002.npz", hull)  # re-carved (hull --overwrite): PLY is stale
    assert not (old / "hulls" / "00002.ply").exists()
    assert np.array_equal(Capture(old)[2].hull_mesh[1], F)


def test_size_limits_give_one_line(monkeypatch, tmp_path, cap):
    from meshmocap.errors import FormatError, MeshError
    from meshmocap.io.meshes import read_mesh, write_mesh

    write_mesh(tmp_path / "m.ply", *Capture(cap)[0].hull_mesh)
    monkeypatch.setenv("MESHMOCAP_MAX_MESH_MB", "0.01")
    with pytest.raises(MeshError, match=r"m\.ply: 0 MB, above the 0 MB limit of one mesh file"):
        read_mesh(tmp_path / "m.ply")
    monkeypatch.setenv("MESHMOCAP_MAX_NPZ_MB", "0.001")
    with pytest.raises(FormatError, match=r"00000\.npz: meshmocap frame file arrays unpack to"):
        _ = Capture(cap)[0].hull
    (tmp_path / "bomb.ply").write_bytes(
        b"ply\nformat ascii 1.0\nelement vertex 99999999999\nproperty float x\nend_header\n"
    )
    monkeypatch.delenv("MESHMOCAP_MAX_MESH_MB")
    with pytest.raises(MeshError, match="header declares 99999999999 elements in a file of"):
        read_mesh(tmp_path / "bomb.ply")


def test_eval_of_a_capture_partly_out_of_view_scores_surfaces_on_frames_in_view(cap, tmp_path):
    from meshmocap.analysis.evaluate import evaluate
    from meshmocap.io.capture import Truth, read_truth, write_truth
    from meshmocap.io.results import FrameResult, start_track, write_frame

    c = tmp_path / "c"
    shutil.copytree(cap, c)
    meta = {"method": "truth", "eval_names": Capture(c).meta["eval_names"]}
    start_track(tmp_path / "t", meta, Capture(c).truth_faces)
    for f in Capture(c):
        write_frame(tmp_path / "t", FrameResult(f.index, f.truth.joints, f.truth.vertices))
    for i in (0, 1):  # the subject of frames 0 and 1 stands 50 m away: out of every view
        tr = read_truth(c / "truth" / f"{i:05d}.npz")
        write_truth(
            c / "truth" / f"{i:05d}.npz",
            Truth(tr.vertices + [50.0, 0, 0], tr.joints, tr.rotations, tr.root),
        )
    ev = evaluate(read_track(tmp_path / "t"), Capture(c), silhouettes=True, surface_frames=8)
    assert ev.out_of_view.tolist() == [0, 1]
    assert ev.surface.frames.tolist() == [2, 3, 4] and np.isfinite(ev.surface.mean).all()
    # nor the silhouettes: frames 0 and 1 are not scored in any camera, the others are
    assert np.isnan(ev.silhouettes.errors[:2]).all() and (ev.silhouettes.true_pixels[:2] == 0).all()
    assert np.isfinite(ev.silhouettes.errors[2:]).all() and ev.silhouettes.overall < 0.2


def test_a_camera_that_does_not_see_the_subject_is_not_scored():
    from meshmocap.analysis.metrics import silhouette_errors
    from meshmocap.analysis.tables import table

    true = np.zeros((2, 2, 4, 4), bool)
    true[:, :, 1:3, 1:3] = True
    true[1, 1] = False  # frame 1: camera B lost the subject (synth kept the frame)
    pred = true.copy()
    pred[0, 0, 0, 0] = True
    se = silhouette_errors(pred, true, cameras=["A", "B"])
    assert np.isnan(se.errors[1, 1]) and se.errors[0, 0] == 0.25
    assert se.per_camera.tolist() == [0.125, 0.0] and se.overall == pytest.approx(0.25 / 3)
    assert "nan" not in table(se).split("pooled")[0].lower()


@pytest.fixture(scope="module")
def killed(tmp_path_factory) -> Path:
    """A track of 12 planned frames killed after 4: frames 0..3 written, frame 2 coasted
    across (flagged missing: it repeats frame 1's values), 4..11 never tracked."""
    from meshmocap.body.procedural import procedural_motion
    from meshmocap.body.template import load_template
    from meshmocap.io.results import FrameResult, start_track, write_frame

    tpl = load_template("neutral_5k")
    root = tmp_path_factory.mktemp("killed")
    (root / "cap").mkdir()
    (root / "cap" / "capture.json").write_text('{"fps": 30.0}')
    m = procedural_motion("walk", tpl, duration=4 / 30.0, fps=30.0)
    posed = tpl.pose(m.rotations[:4], m.root_positions[:4])
    meta = {
        "method": "synthetic",
        "template": "neutral_5k",
        "capture": str(root / "cap"),
        "frames": list(range(12)),
        "eval_names": list(tpl.eval_skeleton.names),
        "eval_parents": tpl.eval_skeleton.parents.tolist(),
    }
    out = root / "t"
    start_track(out, meta, tpl.F, resume=False)
    for k in range(4):
        j = 1 if k == 2 else k  # frame 2: coasted, the last good frame's values
        flags, msg = (("missing",), "only 1 of 4 cameras see the subject") if k == 2 else ((), "")
        r = FrameResult(k, posed.eval_joints[j], posed.V[j], healthy=k != 2, flags=flags)
        write_frame(out, replace(r, message=msg))
    return out


def test_exports_mark_coasted_frames_as_gaps_and_name_frames_never_tracked(killed, tmp_path):
    import csv

    import ezc3d

    from meshmocap.apps.files.export import export_track
    from meshmocap.errors import MissingFrameWarning
    from meshmocap.io.trc import read_trc

    track = read_track(killed)
    never = "8 of the 12 frames track.json planned were never tracked (4–11)"
    got = {}
    for fmt in ("csv", "trc", "c3d", "bvh", "gltf", "glb"):
        with pytest.warns(MissingFrameWarning, match=never.replace("(", r"\(").replace(")", r"\)")):
            got[fmt] = export_track(killed, tmp_path / f"x.{fmt}")
        assert got[fmt].gaps == (2,) and got[fmt].untracked == tuple(range(4, 12))
        assert got[fmt].n_frames == 4 and got[fmt].planned == 12
    ok = np.array([True, True, False, True])
    rows = list(csv.DictReader((tmp_path / "x.csv").read_text().splitlines()))
    assert [r["frame"] for r in rows] == ["0", "1", "2", "3"]
    assert rows[2]["healthy"] == "0" and rows[2]["missing"] == "1"
    assert rows[2]["pelvis_x"] == "" and rows[2]["message"] == "only 1 of 4 cameras see the subject"
    assert float(rows[3]["pelvis_x"]) == pytest.approx(track.joints[3, 0, 0], abs=1e-6)
    trc = read_trc(tmp_path / "x.trc")
    assert np.isnan(trc.points[2]).all() and np.isfinite(trc.points[ok]).all()
    np.testing.assert_allclose(trc.points[ok], track.joints[ok], atol=1e-6)
    c = ezc3d.c3d(str(tmp_path / "x.c3d"))
    assert (c["data"]["meta_points"]["residuals"][0, :, 2] == -1).all()
    assert (c["data"]["meta_points"]["residuals"][0, :, ok] == 0).all()
    pts = c["data"]["points"][:3].transpose(2, 1, 0)
    assert np.isnan(pts[2]).all()  # ezc3d reads the gap as no value
    np.testing.assert_allclose(pts[ok] / 1000, track.joints[ok], atol=1e-6)


def test_a_hole_in_a_track_is_a_gap_and_bvh_holds_the_pose_there(killed, tmp_path, capsys):
    from meshmocap.io.bvh import read_bvh

    t = tmp_path / "t"
    shutil.copytree(killed, t)
    (t / "frames" / "00001.npz").unlink()  # never tracked, between tracked frames
    assert main(["export", str(t), "--out", str(tmp_path / "x.bvh")]) == 0
    out, err = capsys.readouterr()
    assert (
        "2 frames without a fit of their own (coasted or never tracked) held at the last "
        "tracked pose (the format has no gaps): 1–2" in out
    )
    assert err == (
        f"meshmocap: warning: export: {t}: 9 of the 12 frames track.json planned were never "
        "tracked (1, 4–11); 'meshmocap track' with the same arguments resumes them\n"
    )
    m = read_bvh(tmp_path / "x.bvh")
    assert m.rotations.shape[0] == 4  # frames 0..3 at the capture's rate, 1 and 2 held
    np.testing.assert_allclose(m.rotations[1], m.rotations[0], atol=1e-3)  # 0.06°, refitted
    np.testing.assert_allclose(m.rotations[2], m.rotations[0], atol=1e-3)
    assert not np.allclose(m.rotations[3], m.rotations[0])
    assert main(["export", str(t), "--out", str(tmp_path / "x.csv")]) == 0
    out = capsys.readouterr().out
    assert "written as gaps: 1–2" in out
    lines = (tmp_path / "x.csv").read_text().splitlines()
    assert lines[2].startswith("1,0.033333,0,0,0,0,0,never tracked,,,")


def test_a_corrupt_camera_file_fails_its_capture_not_the_batch(cap, tmp_path, capsys):
    bad = tmp_path / "bad"
    shutil.copytree(cap, bad)
    (bad / "cameras.json").write_text('{"cameras": [')  # cut short while copying
    argv = ["batch", str(cap), str(bad), "--frames", "0:2", "--out", str(tmp_path / "b")]
    assert main([*argv, "--method", "articulated_icp", "--template", "neutral_5k", "--serial"]) == 1
    out = capsys.readouterr().out
    assert "batch: 1 of 2 captures tracked" in out
    rows = (tmp_path / "b" / "summary.csv").read_text().splitlines()
    assert rows[1].startswith("cap,") and ",ok," in rows[1]
    assert rows[2].startswith("bad,") and ",failed," in rows[2] and "cameras.json" in rows[2]
    assert len(rows) == 3


def _invert(real: Path, cameras: tuple[str, ...]) -> None:
    from meshmocap.io.silhouettes import read_mask

    for cam in cameras:
        for p in (real / "silhouettes" / cam).glob("*.png"):
            write_mask(p, ~read_mask(p))  # the subject black on white


def test_inverted_silhouettes_are_left_out_of_the_hull_and_track_refuses(cap, tmp_path, capsys):
    real = _real(cap, tmp_path)
    _invert(real, ("C2",))  # one camera's masks drawn the other way round
    assert main(["hull", str(real), "--voxel-size", "0.02"]) == 0
    err = capsys.readouterr().err
    assert err.startswith("meshmocap: warning: 5 frames carved from fewer cameras, first 00000: ")
    assert "carved from 3 of 4 cameras (C2: 9" in err and "% foreground, the others " in err
    assert err.endswith(": inverted?)\n") and err.count("\n") == 1
    V = Capture(real)[0].hull_mesh[0]
    assert (V.max(0) - V.min(0)).max() < 2.0  # the subject, not the studio
    _invert(real, ("C1", "C3", "C4"))  # now every camera: no frame can be carved
    assert main(["hull", str(real), "--voxel-size", "0.02", "--overwrite"]) == 0
    assert "5 frames without hull" in capsys.readouterr().err
    assert main(["track", str(real), *ICP, "--out", str(tmp_path / "t")]) == 2
    err = capsys.readouterr().err
    assert err.startswith(
        f"meshmocap: error: track: no frame of {real} has an observation to start from "
        "(frame 0: only 0 of 4 cameras see the subject (C1: 9"
    )
    assert err.count("\n") == 1 and not (tmp_path / "t").exists()


def test_a_hull_of_the_whole_studio_is_refused_by_track(cap, tmp_path, capsys):
    from meshmocap.geometry.carving import VoxelHull
    from meshmocap.io.capture import write_hull

    c = tmp_path / "c"
    shutil.copytree(cap, c)
    box = np.ones((200, 150, 120), bool)  # 4 × 3 × 2.4 m: what inverted masks carve
    write_hull(c / "hulls" / "00000.npz", VoxelHull(box, np.array([-2.0, -1.5, 0.0]), 0.02))
    assert main(["track", str(c), *ICP, "--out", str(tmp_path / "t")]) == 2
    err = capsys.readouterr().err
    assert err.startswith(
        f"meshmocap: error: track: {c}: frame 0: the observed surface spans 4.0 × 3.0 × 2.4 m, "
        "more than one person (3 m at most): inverted silhouettes (white background) or the "
        "whole scene?"
    )
    assert err.count("\n") == 1


@pytest.mark.slow
def test_frames_carved_from_fewer_cameras_are_named_by_track_and_eval(cap, tmp_path, capsys):
    real = _real(cap, tmp_path)
    empty = np.zeros((480, 640), bool)
    for cam in ("C3", "C4"):  # frame 2 seen by 2 cameras of 4
        write_mask(real / "silhouettes" / cam / "00002.png", empty)
    assert main(["hull", str(real), "--voxel-size", "0.02"]) == 0
    capsys.readouterr()
    assert main(["track", str(real), *ICP, "--frames", "1:4", "--out", str(tmp_path / "t")]) == 0
    note = (
        "1 of 3 frames were carved from fewer than the 4 cameras (first 2: carved from 2 of 4 "
        "cameras (C3: empty mask, C4: empty mask)); their hulls are coarser, and their "
        "silhouettes are scored only in the cameras that saw the subject"
    )
    assert f"meshmocap: warning: track: {note}\n" in capsys.readouterr().err
    assert main(["eval", str(real), str(tmp_path / "t"), "--surface-frames", "0"]) == 0
    assert capsys.readouterr().err == f"meshmocap: warning: eval: {note}\n"


def test_subject_says_a_sphere_is_not_a_performer(tmp_path, capsys):
    import trimesh

    from meshmocap.body.template import load_template
    from meshmocap.io.plausibility import body_problem

    s = trimesh.creation.icosphere(3, 0.9)
    s.apply_translation([0.0, 0.0, 0.9])  # 1.8 m "tall"
    (tmp_path / "m").mkdir()
    s.export(tmp_path / "m" / "s_0.ply")
    assert main(["subject", str(tmp_path / "m"), "--out", str(tmp_path / "s.npz")]) == 0
    err = capsys.readouterr().err
    assert err.startswith(
        f"meshmocap: warning: subject: frame 0 of {tmp_path / 'm'} is not human-like: it fills "
        "52% of its bounding box, a solid blob (a body with its limbs: under 40%"
    )
    assert err.count("\n") == 1
    t = load_template("neutral_5k")
    assert body_problem(t.V, t.F) is None  # the bundled body is human-like
    assert body_problem(0.3 * t.V, t.F) == "it is 0.53 m tall (a person: 0.8–2.5 m)"


def test_subject_warns_on_a_dense_mesh_as_track_does(tmp_path, capsys, monkeypatch):
    """The size warning comes first, before the long estimate (a 1.28M-vertex mesh ran
    229 s without it)."""
    from meshmocap.body.template import load_template
    from meshmocap.io import plausibility
    from meshmocap.io.meshes import write_mesh

    t = load_template("neutral_5k")
    (tmp_path / "m").mkdir()
    write_mesh(tmp_path / "m" / "body_0.ply", t.V, t.F)
    monkeypatch.setattr(plausibility, "MAX_OBSERVED_VERTICES", t.n_vertices - 1)  # as if 1.28M
    assert main(["subject", str(tmp_path / "m"), "--out", str(tmp_path / "s.npz")]) == 0
    out, err = capsys.readouterr()
    assert err == (
        f"meshmocap: warning: subject: frame 0 of {tmp_path / 'm'} has {t.n_vertices:,} "
        f"vertices; above {t.n_vertices - 1:,} tracking is less accurate (decimate the meshes "
        "first: docs/guide/faults.rst)\n"
    )
    assert out.startswith("estimated the performer from frame(s) 0 (mesh")


@pytest.mark.slow
def test_a_dense_mesh_folder_is_tracked_with_a_warning(cap, tmp_path, capsys, monkeypatch):
    from meshmocap.io import plausibility
    from meshmocap.io.meshes import write_mesh

    seq = tmp_path / "seq"
    seq.mkdir()
    for f in list(Capture(cap))[:2]:
        write_mesh(seq / f"m_{f.index}.ply", *f.hull_mesh)
    n = len(Capture(cap)[0].hull_mesh[0])
    monkeypatch.setattr(plausibility, "MAX_OBSERVED_VERTICES", n - 1)  # as if 2.6M > 500k
    assert main(["track", str(seq), *ICP, "--out", str(tmp_path / "t")]) == 0
    err = capsys.readouterr().err
    assert (
        f"meshmocap: warning: track: frame 0 of {seq} has {n:,} vertices; above {n - 1:,} "
        "tracking is less accurate (decimate the meshes first: docs/guide/faults.rst)\n"
    ) in err
