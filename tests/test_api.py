"""The Python API (meshmocap.api): light to import, the CLI's own errors. That its five
lines reproduce the command line's numbers is checked by the documentation's page
(docs/guide/python.rst, a doctest)."""

import subprocess
import sys

import numpy as np
import pytest

import meshmocap
from meshmocap.errors import InputError, MeshmocapFileNotFoundError


def test_import_meshmocap_stays_light():
    code = (
        "import sys, meshmocap; heavy = [m for m in ('scipy', 'sklearn', 'numba', "
        "'matplotlib', 'meshmocap.api') if m in sys.modules]; print(heavy)"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"
    assert meshmocap.track is meshmocap.api.track  # loaded on first use
    assert {"open_capture", "track", "evaluate", "summary"} <= set(dir(meshmocap))
    with pytest.raises(AttributeError, match="no attribute 'trak'"):
        meshmocap.trak  # noqa: B018


def test_mistakes_are_one_line(tmp_path):
    with pytest.raises(InputError, match="found none"):
        meshmocap.open_capture([])
    with pytest.raises(MeshmocapFileNotFoundError, match="no such folder"):
        meshmocap.open_capture(tmp_path / "nope")
    (tmp_path / "cap").mkdir()
    (tmp_path / "cap" / "capture.json").write_text("{}")
    with pytest.raises(InputError, match="is a capture folder"):
        meshmocap.open_capture([tmp_path / "a.obj", tmp_path / "cap"])
    with pytest.raises(InputError, match="method must be one of"):
        meshmocap.track(tmp_path / "cap", method="pach")


@pytest.mark.slow
def test_a_mesh_folder_tracks_and_exports(tmp_path):
    """Three posed frames of neutral_5k as OBJ files, in centimetres with Y up (as many
    tools write them): opened, tracked with articulated ICP, exported, evaluated."""
    from meshmocap.body.procedural import procedural_motion
    from meshmocap.body.template import load_template
    from meshmocap.io.meshes import write_mesh

    template = load_template("neutral_5k")
    m = procedural_motion("walk", template, duration=0.1, fps=30.0)
    posed = template.pose(m.rotations[:3], m.root_positions[:3])
    folder = tmp_path / "meshes"
    folder.mkdir()
    y_up_cm = np.array([[1.0, 0, 0], [0, 0, 1], [0, -1, 0]]) * 100.0
    for k in range(3):
        write_mesh(folder / f"frame_{k:03d}.obj", posed.V[k] @ y_up_cm.T, template.F)
    cap = meshmocap.open_capture(folder)
    assert len(cap) == 3
    axes = meshmocap.api.capture_and_axes(folder)[1]
    assert (axes.up, axes.units) == ("y", "cm")
    track = meshmocap.track(
        cap, method="articulated_icp", template="neutral_5k", out=tmp_path / "t"
    )
    assert track.joints.shape == (3, 15, 3) and track.frames.tolist() == [0, 1, 2]
    assert np.linalg.norm(track.joints - posed.eval_joints, axis=2).mean() < 0.03
    res = track.to_bvh(tmp_path / "walk.bvh")
    assert res.n_frames == 3 and (tmp_path / "walk.bvh").is_file()
    again = meshmocap.open_track(tmp_path / "t")
    np.testing.assert_array_equal(again.joints, track.joints)
    ev = meshmocap.evaluate(cap, track, silhouettes=False, surface_frames=0)
    assert ev.joints is None and ev.n_frames == 3  # a mesh folder has no truth
    assert "3 frames" in meshmocap.summary(ev)
