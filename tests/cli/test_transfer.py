"""``meshmocap transfer`` in process: a cage track's motion replayed on the template as a
mesh file (through Green coordinates, as tracked), on another body scaled to it, and as
one animated glTF; a folder that is no track is one line and status 2."""

import numpy as np
import pytest

from meshmocap.cli import main
from meshmocap.geometry.green import GreenDeformer
from meshmocap.io.meshes import read_mesh, write_mesh
from meshmocap.io.results import read_track
from meshmocap.trackers.cage.oqr import build_oqr
from meshmocap.trackers.cage.transfer import read_cage_track


@pytest.mark.slow
def test_track_with_a_manifold_then_transfer_the_motion(cage_setup, tmp_path, capsys):
    _, t, manifold, cap = cage_setup
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


def test_a_folder_without_track_is_one_line(tmp_path, capsys):
    argv = ["transfer", str(tmp_path / "none"), "heavy_male", "--out", str(tmp_path / "x")]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert (
        err.startswith("meshmocap: error:") and "is not a track folder" in err and "\n" not in err
    )
    assert not (tmp_path / "x").exists()
