"""Studio calibration files (Qualisys, Calib.toml, EasyMocap YAML) into cameras and back."""

import numpy as np
import pytest

from meshmocap.errors import FormatError, InputError, MeshmocapFileNotFoundError
from meshmocap.geometry.camera import Camera, intrinsics, look_at
from meshmocap.geometry.rotations import so3_exp, so3_log
from meshmocap.io.calibration import read_calibration, write_calibration

# One Qualisys camera, written as QTM exports it: position in mm, the rotation's rows (as
# read) the camera's x, −y, −z axes in the world, intrinsics in 1/64 pixel, a video window.
QCA = """<?xml version='1.0' encoding='ASCII'?>
<calibration source="test" type="regular">
  <cameras>
    <camera active="1" serial="cam07" viewrotation="0">
      <fov_video bottom="479" left="16" right="655" top="8"/>
      <transform r11="0.0" r12="1.0" r13="0.0" r21="0.0" r22="0.0" r23="1.0"
                 r31="1.0" r32="0.0" r33="0.0" x="3000.0" y="0.0" z="1000.0"/>
      <intrinsic centerPointU="21504.0" centerPointV="15872.0" focalLengthU="38400.0"
                 focalLengthV="38464.0" radialDistortion1="-0.05" radialDistortion2="0.01"
                 radialDistortion3="0.0" tangentalDistortion1="0.001"
                 tangentalDistortion2="-0.0005" skew="0.0"/>
    </camera>
  </cameras>
</calibration>
"""


def test_qualisys_reads_the_studio_convention(tmp_path):
    path = tmp_path / "Calib.qca.txt"
    path.write_text(QCA)
    (cam,) = read_calibration(path)
    assert cam.name == "cam07" and (cam.width, cam.height) == (640, 472)
    # sub-pixel units / 64, principal point shifted by the window's corner (16, 8);
    # the distortion as it stands (normalised coordinates, as OpenCV's)
    np.testing.assert_allclose(cam.K, [[600.0, 0, 320.0], [0, 601.0, 240.0], [0, 0, 1]])
    np.testing.assert_allclose(cam.dist, [-0.05, 0.01, 0.001, -0.0005, 0.0])
    np.testing.assert_allclose(cam.centre, [3.0, 0.0, 1.0], atol=1e-12)
    # the camera at x = 3 m looks along −x, its image's right is +y, its image's down −z
    np.testing.assert_allclose(cam.R[2], [-1.0, 0.0, 0.0], atol=1e-12)
    uv, depth = cam.project(np.array([[0.0, 0.0, 1.0], [0.0, 0.0, 2.0], [0.0, 1.0, 1.0]]))
    assert depth[0] == pytest.approx(3.0)
    np.testing.assert_allclose(uv[0], [320.0, 240.0], atol=1e-9)  # on the optical axis
    assert uv[1, 1] < 240.0  # up in the world is up in the image (smaller row)
    assert uv[2, 0] > 320.0  # +y is to the right of a camera looking along −x, Z up


def _rig() -> list[Camera]:
    K = intrinsics(640, 480, 55.0)
    K[1, 1] *= 1.001
    R, t = look_at([3.1, -2.9, 2.8], [0.0, 0.0, 0.9])
    c1 = Camera(K, R, t, 640, 480, [0.1, -0.02, 1e-3, -2e-3, 1e-5], "C1")
    R2, t2 = look_at([-3.0, 3.3, 1.5], [0.1, 0.0, 1.0])
    c2 = Camera(intrinsics(800, 600, 45.0), R2, t2, 800, 600, None, "C2")
    return [c1, c2]


def _volume(n: int = 200, half: float = 1.0) -> np.ndarray:
    rng = np.random.default_rng(0)
    return rng.uniform([-half, -half, 0.0], [half, half, 2.0], size=(n, 3))


def _max_reprojection(a: list[Camera], b: list[Camera], X: np.ndarray) -> float:
    assert [c.name for c in a] == [c.name for c in b]
    assert [(c.width, c.height) for c in a] == [(c.width, c.height) for c in b]
    return max(
        np.abs(ca.project(X)[0] - cb.project(X)[0]).max() for ca, cb in zip(a, b, strict=True)
    )


@pytest.mark.parametrize("name", ["rig.qca.txt", "Calib.toml", "rig.yml", "rig.json"])
def test_every_format_round_trips(tmp_path, name):
    cams = _rig()
    write_calibration(tmp_path / name, cams)
    back = read_calibration(tmp_path / name)
    assert _max_reprojection(cams, back, _volume()) < 1e-6
    for a, b in zip(cams, back, strict=True):
        np.testing.assert_allclose(b.dist, a.dist, atol=1e-15)


def test_toml_in_millimetres_and_pose2sim_layout(tmp_path):
    R, t = look_at([2.0, -3.0, 1.5], [0.0, 0.0, 1.0])
    w = so3_log(R).tolist()
    tm = (t * 1000).tolist()
    text = (
        "[cam_0]\n"
        'name = "left"\n'
        "size = [ 1280.0, 720.0,]\n"
        "matrix = [ [ 1000.0, 0.0, 640.0,], [ 0.0, 1000.0, 360.0,], [ 0.0, 0.0, 1.0,],]\n"
        "distortions = [ -0.1, 0.02, 0.0, 0.0,]\n"
        f"rotation = [ {w[0]!r}, {w[1]!r}, {w[2]!r},]\n"
        f"translation = [ {tm[0]!r}, {tm[1]!r}, {tm[2]!r},]\n"
        "fisheye = false\n\n[metadata]\nadjusted = false\nerror = 0.0\n"
    )
    path = tmp_path / "calibration.toml"
    path.write_text(text)
    (cam,) = read_calibration(path, unit="mm")
    assert cam.name == "left" and cam.shape == (720, 1280)
    np.testing.assert_allclose(cam.R, so3_exp(w), atol=1e-12)
    np.testing.assert_allclose(cam.centre, [2.0, -3.0, 1.5], atol=1e-9)
    np.testing.assert_allclose(cam.dist, [-0.1, 0.02, 0, 0, 0])
    path.write_text(text.replace("fisheye = false", "fisheye = true"))
    with pytest.raises(FormatError, match=r"\[cam_0\].*fisheye"):
        read_calibration(path)


def test_easymocap_intri_and_extri(tmp_path):
    (tmp_path / "intri.yml").write_text(
        '%YAML:1.0\n---\nnames:\n  - "01"\n'
        "K_01: !!opencv-matrix\n  rows: 3\n  cols: 3\n  dt: d\n"
        "  data: [ 900.0, 0.0, 320.0, 0.0, 900.0, 240.0, 0.0, 0.0, 1.0 ]\n"
        "dist_01: !!opencv-matrix\n  rows: 1\n  cols: 5\n  dt: d\n"
        "  data: [ 0.05, -0.01, 0.0, 0.0, 0.0 ]\n"
        "imgSize_01: [ 640, 480 ]\n"
    )
    (tmp_path / "extri.yml").write_text(
        '%YAML:1.0\n---\nnames:\n  - "01"\n'
        "R_01: !!opencv-matrix\n  rows: 3\n  cols: 1\n  dt: d\n  data: [ 0.0, 0.0, 0.5 ]\n"
        "T_01: !!opencv-matrix\n  rows: 3\n  cols: 1\n  dt: d\n  data: [ 0.1, 0.2, 3.0 ]\n"
    )
    (cam,) = read_calibration(tmp_path / "intri.yml", extrinsics=tmp_path / "extri.yml")
    assert cam.name == "01" and cam.K[0, 0] == 900.0
    np.testing.assert_allclose(cam.R, so3_exp([0.0, 0.0, 0.5]))
    np.testing.assert_allclose(cam.t, [0.1, 0.2, 3.0])


@pytest.mark.parametrize(
    ("text", "match"),
    [
        ("<calibration><cameras></cameras></calibration>", "not a Qualisys calibration"),
        ("<calibration><cameras><camera", "not valid XML"),
        (QCA.replace(' focalLengthU="38400.0"', ""), "'cam07'.*focalLengthU"),
        (QCA.replace('r11="0.0"', 'r11="0.5"'), "not a rotation"),
        (QCA.replace('x="3000.0"', 'x="nan"'), "x='nan' is not a finite number"),
    ],
)
def test_qualisys_errors_name_the_field(tmp_path, text, match):
    path = tmp_path / "bad.qca.txt"
    path.write_text(text)
    with pytest.raises(FormatError, match=match):
        read_calibration(path)


def test_other_errors(tmp_path):
    with pytest.raises(MeshmocapFileNotFoundError, match="no such file"):
        read_calibration(tmp_path / "absent.toml")
    (tmp_path / "x.toml").write_text("[metadata]\nerror = 0.0\n")
    with pytest.raises(FormatError, match="no cameras found"):
        read_calibration(tmp_path / "x.toml")
    with pytest.raises(InputError, match="format must be one of"):
        read_calibration(tmp_path / "x.toml", format="vicon")
    with pytest.raises(InputError, match="cannot tell the format"):
        write_calibration(tmp_path / "rig.txt", _rig())


def test_pose2sim_demo_reprojects_after_round_trips(shared_data, tmp_path):
    # The real Qualisys file: portrait 1088×1920 cameras 2.5 to 4.5 m from a force plate at the
    # origin; through every format and back, points of the volume reproject within 0.5 px.
    path = shared_data / "video" / "pose2sim_demo" / "Calib.qca.txt"
    if not path.is_file():
        pytest.skip(f"Pose2Sim demo not available: {path} is absent")
    cams = read_calibration(path)
    assert [c.name for c in cams] == ["cam01", "cam02", "cam03", "cam04"]
    assert all(c.shape == (1920, 1088) for c in cams)
    # the lens' distortion, of the magnitude the same cameras' charuco calibration gives
    assert all(-0.06 < c.dist[0] < -0.03 and 0.1 < c.dist[1] < 0.2 for c in cams)
    X = _volume(half=0.5)  # a person's volume over the plate
    for c in cams:  # the volume is in front of every camera and mostly in its image
        uv, depth = c.project(X)
        assert np.all(depth > 1.0) and np.all(depth < 6.0)
        inside = (uv >= 0).all(axis=1) & (uv[:, 0] < c.width) & (uv[:, 1] < c.height)
        assert inside.mean() > 0.7
    for name in ("back.qca.txt", "Calib.toml", "cameras.yml", "cameras.json"):
        write_calibration(tmp_path / name, cams)
        back = read_calibration(tmp_path / name)
        assert _max_reprojection(cams, back, X) < 0.5
