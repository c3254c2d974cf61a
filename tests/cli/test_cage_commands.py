"""The cage tracker from the command line: learn, track --method cage, transfer (in-process)."""

from __future__ import annotations

import numpy as np
import pytest

from meshmocap.body.template import load_template
from meshmocap.cli import main
from meshmocap.geometry.green import GreenDeformer
from meshmocap.io.meshes import read_mesh, write_mesh
from meshmocap.io.results import read_track
from meshmocap.studio.synth import SynthSpec, synthesize
from meshmocap.trackers.cage.manifold import PoseManifold, fit_pose_manifold
from meshmocap.trackers.cage.oqr import build_oqr
from meshmocap.trackers.cage.training_poses import load_pose_sources
from meshmocap.trackers.cage.transfer import read_cage_track


@pytest.fixture(scope="module")
def setup(tmp_path_factory):
    """A small saved manifold of neutral_5k and a 3-frame synthetic walk capture."""
    root = tmp_path_factory.mktemp("cli_cage")
    t = load_template("neutral_5k")
    oqr = build_oqr(t)
    poses = load_pose_sources(["walk"], t, oqr=oqr, duration=1.2, fps=15.0)
    manifold = fit_pose_manifold(poses, t, oqr=oqr, n_samples=18, max_iter=200).save(
        root / "manifold.npz"
    )
    spec = SynthSpec(motion="walk", template="neutral_5k", stop=6, step=2, voxel_size=0.02)
    cap = synthesize(root / "cap", spec, show_progress=False)
    return root, t, manifold, cap


def test_learn_prints_a_summary_and_writes_manifold_and_plot(tmp_path, capsys):
    out, png = tmp_path / "m.npz", tmp_path / "latent.png"
    args = ["learn", "walk", "jog", "--samples", "16", "--out", str(out), "--plot", str(png)]
    assert main(args) == 0
    text = capsys.readouterr().out
    assert "read 242 poses of 'neutral_5k' from 2 source(s)" in text
    assert "learned a 2-D manifold from 16 poses (8 jog, 8 walk)" in text
    assert "final log-likelihood" in text and "L-BFGS-B iterations" in text
    pm = PoseManifold.load(out)
    assert (pm.n_samples, pm.n_components, pm.template_name) == (16, 2, "neutral_5k")
    assert png.stat().st_size > 10_000 and png.read_bytes()[:4] == b"\x89PNG"


def test_learn_from_the_bundled_pose_library_and_a_task_motion(tmp_path, capsys):
    """A task-specific manifold: the library's first poses beside a procedural jog."""
    out = tmp_path / "m.npz"
    assert main(["learn", "library:40", "jog", "--samples", "30", "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "read 161 poses of 'neutral_5k' from 2 source(s)" in text
    groups = set(PoseManifold.load(out).groups)
    assert "jog" in groups and len(groups - {"jog"}) >= 3  # library categories


def test_learn_from_the_cmu35_walk_jog_mat(cmu, tmp_path, capsys):
    mat = cmu / "cmu35WalkJog.mat"
    if not mat.is_file():
        pytest.skip(f"{mat} is absent")
    out = tmp_path / "m.npz"
    assert main(["learn", str(mat), "--samples", "40", "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "read 2644 poses" in text and "from 40 poses (" in text and "jog" in text
    assert set(PoseManifold.load(out).groups) == {"walk", "jog"}


@pytest.mark.slow
def test_track_with_a_manifold_then_transfer_the_motion(setup, tmp_path, capsys):
    _, t, manifold, cap = setup
    track_dir = tmp_path / "track"
    args = [
        "track",
        str(cap.path),
        "--method",
        "cage_nolocal",
        "--manifold",
        str(manifold),
        "--init",
        "truth",
    ]
    assert main([*args, "--out", str(track_dir)]) == 0
    assert "tracked 3 frames with cage_nolocal" in capsys.readouterr().out
    track = read_track(track_dir)
    # the template itself, as a mesh file, replays the track's cages through Green
    # coordinates (to float32 storage); the track's own vertices are skinned (surface=)
    write_mesh(tmp_path / "me.obj", t.V, t.F)
    cages = read_cage_track(track_dir).cages
    oqr = build_oqr(t)
    expected = GreenDeformer(oqr.rest_vertices, oqr.faces, t.V).deform(cages[2])
    assert (
        main(["transfer", str(track_dir), str(tmp_path / "me.obj"), "--out", str(tmp_path / "me")])
        == 0
    )
    captured = capsys.readouterr()
    assert "3 written, 0 already there; 0 vertices outside" in captured.out
    assert captured.err == ""
    V, _ = read_mesh(tmp_path / "me" / "frame_00004.obj")
    assert np.abs(V - expected).max() < 1e-5
    assert np.abs(track.vertices[2] - expected).max() < 0.1  # the same body, within 10 cm
    # another body, scaled to the template's height: a few vertices still stick out
    heavy = ["transfer", str(track_dir), "heavy_male", "--fit", "scale", "--out"]
    assert main([*heavy, str(tmp_path / "heavy")]) == 0
    captured = capsys.readouterr()
    assert "3 written" in captured.out and "scale 0.944/0.944/0.944" in captured.out
    assert captured.err.startswith("meshmocap: warning: write_transfer:")
    assert len(sorted((tmp_path / "heavy").glob("frame_*.obj"))) == 3
    # one animated glTF instead of one mesh per frame
    assert main([*heavy, str(tmp_path / "anim"), "--format", "glb", "--outside", "ignore"]) == 0
    assert "3 written" in capsys.readouterr().out
    assert [p.name for p in (tmp_path / "anim").glob("*.glb")] == ["transfer.glb"]


def test_user_mistakes_give_one_line_and_status_2(setup, tmp_path, capsys):
    _, _, manifold, cap = setup
    cases = [
        (
            [
                "track",
                str(cap.path),
                "--method",
                "cage",
                "--manifold",
                str(manifold),
                "--template",
                "heavy_male",
                "--out",
                str(tmp_path / "t"),
            ],
            "manifold was built for template 'neutral_5k'",
        ),
        (
            ["track", str(cap.path), "--manifold", str(manifold), "--out", str(tmp_path / "t")],
            "a manifold is only used by",
        ),
        (["learn", "walkk", "--out", str(tmp_path / "m.npz")], "expected one of"),
        (
            ["learn", "walk", "--samples", "0", "--out", str(tmp_path / "m.npz")],
            "argument --samples: expected an integer from 3 to 100000, found '0'",
        ),
        (["learn", "walk", "--out", str(tmp_path / "no" / "m.npz")], "in an existing folder"),
        (
            ["transfer", str(tmp_path / "none"), "heavy_male", "--out", str(tmp_path / "x")],
            "has no track.json",
        ),
    ]
    for args, message in cases:
        assert main(args) == 2
        err = capsys.readouterr().err.strip()
        assert err.startswith("meshmocap: error:") and message in err and "\n" not in err
    assert not (tmp_path / "t" / "frames").exists()  # refused before tracking
    assert not (tmp_path / "m.npz").exists()


@pytest.mark.slow
def test_cage_tracks_a_folder_of_meshes_in_millimetres(setup, tmp_path, capsys):
    # ~15 s: the automatic first pose (a mesh folder has no truth); the cage needs a distance
    # field, made from each mesh (estimate.recovery.observe)
    _, t, manifold, cap = setup
    folder = tmp_path / "meshes"
    folder.mkdir()
    for k, f in enumerate(cap):  # numbered 0, 1, 2: a gap in the names is a missing frame
        write_mesh(folder / f"f{k:03d}.obj", f.truth.vertices * 1000, t.F)
    out = tmp_path / "t"
    # the manifold's body (the default would estimate one)
    args = [
        "track",
        str(folder),
        "--method",
        "cage_nolocal",
        "--manifold",
        str(manifold),
        "--template",
        "neutral_5k",
    ]
    assert main([*args, "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "Z up, mm, a body 1.7" in text and "tracked 3 frames with cage_nolocal" in text
    assert "init auto:" in text
    track = read_track(out)
    true = np.stack([f.truth.joints for f in cap])
    err = np.linalg.norm(track.joints - true, axis=2).mean(axis=1) * 1000
    assert err.max() < 30.0  # measured 9, 10, 14 mm
