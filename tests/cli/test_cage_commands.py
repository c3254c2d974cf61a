"""The cage tracker from the command line (in-process): ``track --method cage`` with a saved
manifold (``learn``: tests/cli/test_learn.py; ``transfer``: tests/cli/test_transfer.py)."""

from __future__ import annotations

import numpy as np
import pytest

from meshmocap.cli import main
from meshmocap.io.meshes import write_mesh
from meshmocap.io.results import read_track


def test_user_mistakes_give_one_line_and_status_2(cage_setup, tmp_path, capsys):
    _, _, manifold, cap = cage_setup
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
    ]
    for args, message in cases:
        assert main(args) == 2
        err = capsys.readouterr().err.strip()
        assert err.startswith("meshmocap: error:") and message in err and "\n" not in err
    assert not (tmp_path / "t" / "frames").exists()  # refused before tracking


@pytest.mark.slow
def test_cage_tracks_a_folder_of_meshes_in_millimetres(cage_setup, tmp_path, capsys):
    # ~15 s: the automatic first pose (a mesh folder has no truth); the cage needs a distance
    # field, made from each mesh (estimate.recovery.observe)
    _, t, manifold, cap = cage_setup
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
