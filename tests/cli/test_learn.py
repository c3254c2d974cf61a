"""``meshmocap learn`` in process: a pose manifold learned from procedural motions, the
bundled pose library or a CMU file, its summary printed, its file and plot written; a
user's mistake is one line and status 2."""

import pytest

from meshmocap.cli import main
from meshmocap.trackers.cage.manifold import PoseManifold


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


def test_user_mistakes_give_one_line_and_status_2(tmp_path, capsys):
    cases = [
        (["learn", "walkk", "--out", str(tmp_path / "m.npz")], "expected one of"),
        (
            ["learn", "walk", "--samples", "0", "--out", str(tmp_path / "m.npz")],
            "argument --samples: expected an integer from 3 to 100000, found '0'",
        ),
        (["learn", "walk", "--out", str(tmp_path / "no" / "m.npz")], "in an existing folder"),
    ]
    for args, message in cases:
        assert main(args) == 2
        err = capsys.readouterr().err.strip()
        assert err.startswith("meshmocap: error:") and message in err and "\n" not in err
    assert not (tmp_path / "m.npz").exists()
