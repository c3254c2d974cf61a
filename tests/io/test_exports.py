"""The export writers on their own: round trips through this library's readers, and the
mistakes they refuse."""

import numpy as np
import pytest

from meshmocap.body.template import load_template
from meshmocap.errors import InputError
from meshmocap.io.c3d import read_c3d, write_c3d
from meshmocap.io.gltf import morph_gltf, skinned_gltf, write_gltf
from meshmocap.io.joints_csv import write_joints_csv
from meshmocap.io.trc import Z_UP_TO_OPENSIM, read_trc, write_trc


@pytest.fixture(scope="module")
def points():
    return np.random.default_rng(0).normal(0.0, 0.5, (5, 3, 3))


def test_trc_and_c3d_round_trip(points, tmp_path):
    write_trc(tmp_path / "a.trc", points, ["a", "b", "c"], 50.0, first_frame=7, start_time=0.14)
    m = read_trc(tmp_path / "a.trc")
    np.testing.assert_allclose(m.points, points, atol=1e-9)  # 6 decimals of mm
    np.testing.assert_allclose(m.times, 0.14 + np.arange(5) / 50.0, atol=1e-6)
    assert m.labels == ("a", "b", "c") and m.fps == 50.0 and m.first_frame == 7
    assert np.allclose(Z_UP_TO_OPENSIM @ [0, -1, 0], [1, 0, 0])  # facing −Y → OpenSim's +X
    assert np.isclose(np.linalg.det(Z_UP_TO_OPENSIM), 1.0)
    write_c3d(
        tmp_path / "a.c3d",
        points,
        ["a", "b", "c"],
        50.0,
        first_frame=7,
        valid=np.array([1, 1, 0, 1, 1], bool),
    )
    c = read_c3d(tmp_path / "a.c3d")
    ok = np.arange(5) != 2
    np.testing.assert_allclose(c.points[ok], points[ok], atol=1e-7)  # float32 millimetres
    assert np.isnan(c.points[2]).all() and c.first_frame == 7 and c.fps == 50.0


def test_writers_refuse_bad_input(points, tmp_path):
    with pytest.raises(InputError, match="NaN"):
        write_trc(tmp_path / "a.trc", np.full((2, 1, 3), np.nan), ["a"], 30.0)
    with pytest.raises(InputError, match="distinct labels"):
        write_c3d(tmp_path / "a.c3d", points, ["a", "a", "b"], 30.0)
    with pytest.raises(InputError, match="fps"):
        write_trc(tmp_path / "a.trc", points, ["a", "b", "c"], 0.0)
    with pytest.raises(InputError, match="NaN"):
        write_joints_csv(tmp_path / "a.csv", np.full((1, 1, 3), np.inf), ["a"], [0], 30.0)
    t = load_template("neutral_5k")
    R = np.tile(np.eye(3), (2, 31, 1, 1))
    with pytest.raises(InputError, match="times must increase"):
        skinned_gltf(t.V, t.F, t.skeleton, t.weights, R, np.zeros((2, 3)), [0.0, 0.0])
    with pytest.raises(InputError, match=r"rotations must have shape \(·, 31, 3, 3\)"):
        skinned_gltf(t.V, t.F, t.skeleton, t.weights, R[:, :5], np.zeros((2, 3)), [0.0, 1.0])
    with pytest.raises(InputError, match="F indexes vertices"):
        morph_gltf(t.V[None, :10], t.F, [0.0])
    with pytest.raises(InputError, match=r"must end in \.glb or \.gltf"):
        write_gltf(tmp_path / "a.obj", morph_gltf(t.V[None], t.F, [0.0]))
