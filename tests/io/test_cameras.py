"""Camera rig files (JSON, OpenCV YAML), the distortion model, and the preset rigs."""

import re

import numpy as np
import pytest

from meshmocap.errors import FormatError, InputError, MeshmocapFileNotFoundError
from meshmocap.geometry.camera import Camera, in_view, intrinsics, look_at
from meshmocap.geometry.rotations import so3_exp
from meshmocap.io.cameras import read_cameras, write_cameras
from meshmocap.studio.rigs import VOLUME_HEIGHT, camera_rig


def _rig() -> list[Camera]:
    K = intrinsics(640, 480, 55.0)
    K[0, 1] = 0.25  # a skew, to check every entry travels
    R, t = look_at([3.1, -2.9, 2.8], [0.0, 0.0, 0.9])
    c1 = Camera(K, R, t, 640, 480, [0.1, -0.02, 1e-3, -2e-3, 1e-5], "C1")
    R2, t2 = look_at([-3.0, 3.3, 1.5], [0.1, 0.0, 1.0])
    c2 = Camera(intrinsics(800, 600, 45.0), R2, t2 + 1e-17, 800, 600, None, "C2")
    return [c1, c2]


def _same(a: Camera, b: Camera) -> bool:
    arrays = all(np.array_equal(getattr(a, k), getattr(b, k)) for k in ("K", "R", "t", "dist"))
    return arrays and (a.name, a.width, a.height) == (b.name, b.width, b.height)


@pytest.mark.parametrize("suffix", [".json", ".yml", ".yaml"])
def test_round_trip_is_bit_exact(tmp_path, suffix):
    # Numbers are written in Python's shortest round-trip form: equality, not closeness.
    cams = _rig()
    path = tmp_path / f"rig{suffix}"
    write_cameras(path, cams)
    back = read_cameras(path)
    assert len(back) == 2 and all(_same(a, b) for a, b in zip(cams, back, strict=True))
    assert [p.name for p in tmp_path.iterdir()] == [path.name]  # no temporary file left


def test_opencv_millimetres(tmp_path):
    # t is scaled by 1000 and back: equal to within 2 ulp (one multiply, one divide).
    cams = _rig()
    write_cameras(tmp_path / "rig.yml", cams, unit="mm")
    back = read_cameras(tmp_path / "rig.yml", unit="mm")
    for a, b in zip(cams, back, strict=True):
        np.testing.assert_allclose(b.t, a.t, rtol=5e-16, atol=1e-30)
        assert np.array_equal(a.R, b.R)


OPENCV_FILE = """%YAML:1.0
---
names:
   - "0"
   - "side"
K_0: !!opencv-matrix
   rows: 3
   cols: 3
   dt: d
   data: [ 1.0000000000000000e+03, 0., 3.1950000000000000e+02, 0.,
       1.0000000000000000e+03, 2.3950000000000000e+02, 0., 0., 1. ]
dist_0: !!opencv-matrix
   rows: 1
   cols: 5
   dt: d
   data: [ -1.0000000000000001e-01, 0., 0., 0., 0. ]
R_0: !!opencv-matrix
   rows: 3
   cols: 3
   dt: d
   data: [ 1., 0., 0., 0., 0., -1., 0., 1., 0. ]
t_0: !!opencv-matrix
   rows: 3
   cols: 1
   dt: d
   data: [ 0., 1.0, 4. ]
imgSize_0: [ 640, 480 ]
K_side: !!opencv-matrix
   rows: 3
   cols: 3
   dt: f
   data: [ 500., 0., 160., 0., 500., 120., 0., 0., 1. ]
dist_side: !!opencv-matrix
   rows: 8
   cols: 1
   dt: d
   data: [ 0., 0., 0., 0., 0., 0., 0., 0. ]
R_side: [ 0.0, 0.0, 1.5707963267948966 ]
T_side: [ 0, 0, 3000 ]
W_side: 320
H_side: 240
"""


def test_reads_opencv_filestorage_and_projects_a_known_point(tmp_path):
    path = tmp_path / "calib.yml"
    path.write_text(OPENCV_FILE)
    c0, side = read_cameras(path, unit="mm")
    assert (c0.name, c0.shape, side.name, side.shape) == ("0", (480, 640), "side", (240, 320))
    assert c0.dist[0] == -0.1 and np.all(side.dist == 0)
    # R_0 maps world +Z (up) to camera −y (up in the image), world +Y to depth.
    # X = (0.2, 1.0, 1.0) m: X_cam = R X + t = (0.2, −1 + 0.001, 1 + 0.004) with t in mm.
    Xc = np.array([0.2, -1.0 + 0.001, 1.0 + 0.004])
    x, y = Xc[:2] / Xc[2]
    radial = 1 - 0.1 * (x * x + y * y)
    uv, depth = c0.project(np.array([0.2, 1.0, 1.0]))
    np.testing.assert_allclose(depth, 1.004, rtol=1e-15)
    np.testing.assert_allclose(uv, [1000 * x * radial + 319.5, 1000 * y * radial + 239.5])
    # Rodrigues vector (0, 0, π/2): a quarter turn about camera z; T_side in mm.
    np.testing.assert_allclose(side.R, so3_exp([0, 0, np.pi / 2]), atol=1e-15)
    np.testing.assert_allclose(side.t, [0, 0, 3.0])


def test_reads_split_intrinsics_and_extrinsics(tmp_path):
    # EasyMocap keeps K/dist in intri.yml and R (Rodrigues)/Rot/T in extri.yml.
    intri = tmp_path / "intri.yml"
    extri = tmp_path / "extri.yml"
    intri.write_text(
        '%YAML:1.0\n---\nnames:\n  - "01"\nK_01: !!opencv-matrix\n  rows: 3\n  cols: 3\n'
        "  dt: d\n  data: [800., 0., 320., 0., 800., 240., 0., 0., 1.]\n"
        "dist_01: !!opencv-matrix\n  rows: 1\n  cols: 5\n  dt: d\n  data: [0.01, 0, 0, 0, 0]\n"
    )
    rot = so3_exp([0.1, -0.2, 0.3])
    data = ", ".join(repr(float(v)) for v in rot.ravel())
    extri.write_text(
        "%YAML:1.0\n---\nnames: ['01']\nR_01: !!opencv-matrix\n  rows: 3\n  cols: 1\n  dt: d\n"
        "  data: [0.1, -0.2, 0.3]\n"
        f"Rot_01: !!opencv-matrix\n  rows: 3\n  cols: 3\n  dt: d\n  data: [{data}]\n"
        "T_01: !!opencv-matrix\n  rows: 3\n  cols: 1\n  dt: d\n  data: [0.5, 0.25, 4.0]\n"
    )
    with pytest.raises(FormatError, match=r"intri\.yml: camera '01': missing key 'R_01'"):
        read_cameras(intri, image_size=(640, 480))
    (cam,) = read_cameras(intri, extrinsics=extri, image_size=(640, 480))
    assert np.array_equal(cam.R, rot) and np.array_equal(cam.t, [0.5, 0.25, 4.0])
    assert cam.shape == (480, 640) and cam.dist[0] == 0.01


def test_reads_a_single_camera_calibration(tmp_path):
    path = tmp_path / "webcam.yaml"
    path.write_text(
        "%YAML:1.0\nimage_width: 640\nimage_height: 480\ncamera_matrix: !!opencv-matrix\n"
        "   rows: 3\n   cols: 3\n   dt: d\n"
        "   data: [ 600., 0., 320., 0., 600., 240., 0., 0., 1. ]\n"
        "distortion_coefficients: !!opencv-matrix\n   rows: 5\n   cols: 1\n   dt: d\n"
        "   data: [ 0.1, 0., 0., 0., 0. ]\n"
    )
    (cam,) = read_cameras(path)
    assert cam.name == "webcam" and cam.shape == (480, 640) and cam.K[0, 0] == 600
    assert np.array_equal(cam.R, np.eye(3)) and np.array_equal(cam.t, np.zeros(3))


def test_distortion_follows_the_opencv_formula():
    # One point by hand: x = 0.2, y = -0.1 (normalised), r² = 0.05,
    # radial = 1 + 0.1·0.05 + 0.01·0.05² + 0.001·0.05³ = 1.005025125,
    # x' = 0.2·radial + 2·0.001·(0.2·-0.1) + (-0.002)·(0.05 + 2·0.04) = 0.200705025
    # y' = -0.1·radial + 0.001·(0.05 + 2·0.01) + 2·(-0.002)·(0.2·-0.1) = -0.1003525125
    K = np.array([[500.0, 0, 320], [0, 400.0, 240], [0, 0, 1]])
    cam = Camera(K, np.eye(3), np.zeros(3), 640, 480, [0.1, 0.01, 0.001, -0.002, 0.001])
    uv, _ = cam.project(np.array([0.4, -0.2, 2.0]))
    np.testing.assert_allclose(uv, [500 * 0.200705025 + 320, 400 * -0.1003525125 + 240], atol=1e-9)


@pytest.mark.parametrize(
    ("name", "text", "message"),
    [
        ("a.json", '{"cameras": [', r"a\.json:1: not valid JSON"),
        ("b.json", '{"cameras": [{"K": 1}]}', r"b\.json: camera 0 \('cam0'\): unknown|missing"),
        (
            "c.json",
            '[{"K": [1, 2], "R": [[1,0,0],[0,1,0],[0,0,1]], "t": [0,0,1], "width": 8,'
            ' "height": 8}]',
            r"c\.json: camera 0 \('cam0'\): key 'K' must be a 3×3 matrix",
        ),
        (
            "d.json",
            '[{"K": [[1,0,0],[0,1,0],[0,0,1]], "R": [[1,0,0],[0,1,0],[0,0,1]], "t": [0,0,1],'
            ' "width": 8.5, "height": 8, "dsit": []}]',
            r"d\.json: camera 0 \('cam0'\): unknown keys \['dsit'\]",
        ),
        (
            "e.json",
            '[{"K": [[1,0,0],[0,1,0],[0,0,1]], "R": [[1,0,0],[0,1,0],[0,0,2]], "t": [0,0,1],'
            ' "width": 8, "height": 8}]',
            r"e\.json: camera 0 \('cam0'\): R is not a rotation",
        ),
        ("f.yml", "%YAML:1.0\nK_a: [1, 2\nR_a: 3\n", r"f\.yml:3: not valid YAML"),
        ("g.yml", "%YAML:1.0\nfoo: 1\n", r"g\.yml: no cameras found"),
        (
            "h.yml",
            "%YAML:1.0\nK_a: !!opencv-matrix\n  rows: 3\n  cols: 3\n  dt: d\n  data: [1, 0, 0]\n",
            r"h\.yml: camera 'a': key 'K_a': !!opencv-matrix has rows×cols = 9 but 3",
        ),
        (
            "i.yml",
            "%YAML:1.0\nK_a: [1, 0, 0, 0, 1, 0, 0, 0, 1]\nR_a: [0, 0, 0]\nt_a: [0, 0, 1]\n"
            "imgSize_a: [8, 8]\ndist_a: [0, 0, 0, 0, 0, 0.5, 0, 0]\n",
            r"i\.yml: camera 'a': key 'dist_a': only \(k1, k2, p1, p2, k3\)",
        ),
        (
            "j.yml",
            "%YAML:1.0\nK_a: [1, 0, 0, 0, 1, 0, 0, 0, 1]\nR_a: [0, 0, 0]\nt_a: [0, 0, 1]\n",
            r"j\.yml: camera 'a': no image size",
        ),
        ("k.yml", "%YAML:1.0\nnames: cam0\n", r"k\.yml: key 'names' must be a non-empty list"),
        (
            "l.yml",
            "%YAML:1.0\nK_a: [1, 0, 0, 0, 1, 0, 0, 0, 1]\nR_a: [0, 0, x]\nt_a: [0, 0, 1]\n",
            r"l\.yml: camera 'a': key 'R_a' must be a 3×3 rotation or an axis-angle",
        ),
    ],
)
def test_malformed_files_raise_one_line_format_errors(tmp_path, name, text, message):
    path = tmp_path / name
    path.write_text(text)
    with pytest.raises(FormatError, match=message) as info:
        read_cameras(path)
    assert str(info.value).startswith(str(path)) and "\n" not in str(info.value)


def test_missing_file_and_bad_options(tmp_path):
    with pytest.raises(MeshmocapFileNotFoundError, match=re.escape(str(tmp_path / "no.json"))):
        read_cameras(tmp_path / "no.json")
    with pytest.raises(InputError, match=r"format must be one of \['auto', 'json', 'opencv'\]"):
        read_cameras(tmp_path / "no.json", format="xml")
    with pytest.raises(InputError, match="cannot tell the format"):
        write_cameras(tmp_path / "rig.txt", _rig())
    with pytest.raises(InputError, match="names must be distinct"):
        write_cameras(tmp_path / "rig.json", [_rig()[0], _rig()[0]])
    bad = Camera(np.eye(3), np.eye(3), np.zeros(3), 8, 8, None, "cam 0")
    with pytest.raises(InputError, match="OpenCV camera names"):
        write_cameras(tmp_path / "rig.yml", [bad])


@pytest.mark.parametrize("name", ["humaneva4", "ring8"])
def test_preset_rigs_see_a_person_anywhere_in_the_volume(name):
    cams = camera_rig(name)
    # A 2 m person standing within 1.5 m of the centre lies inside the cylinder r ≤ 1.5 m,
    # 0 ≤ z ≤ 2 m: sample its inside and its rims (the extreme points of its image).
    rng = np.random.default_rng(0)
    r = 1.5 * np.sqrt(rng.random(4000))
    a = rng.uniform(0, 2 * np.pi, 4000)
    inside = np.column_stack([r * np.cos(a), r * np.sin(a), rng.uniform(0, VOLUME_HEIGHT, 4000)])
    b = np.linspace(0, 2 * np.pi, 3600, endpoint=False)
    rims = [np.column_stack([1.5 * np.cos(b), 1.5 * np.sin(b), np.full(b.size, z)]) for z in (0, 2)]
    X = np.concatenate([inside, *rims])
    for cam in cams:
        uv, depth = cam.project(X)
        assert (depth > 0).all()
        assert (uv >= 0).all() and (uv[:, 0] <= cam.width - 1).all()
        assert (uv[:, 1] <= cam.height - 1).all()
        # ... and the person is not tiny: at the centre, 2 m span ≥ 35 % of the image height.
        (_, top), (_, bottom) = cam.project(np.array([[0, 0, 2.0], [0, 0, 0.0]]))[0]
        assert bottom - top > 0.35 * cam.height
        # Every camera looks at the centre: it projects to the principal point.
        np.testing.assert_allclose(cam.project(np.array([0, 0, 0.9]))[0], cam.K[:2, 2], atol=1e-9)


def test_preset_layouts():
    he = camera_rig("humaneva4")
    centres = np.array([c.centre for c in he])
    assert len(he) == 4 and [c.name for c in he] == ["C1", "C2", "C3", "C4"]
    assert (centres[:, 2] >= 2.5).all() and (centres[:, 2] <= 3.0).all()
    assert (np.hypot(*centres[:, :2].T) >= 4.0).all() and (np.hypot(*centres[:, :2].T) <= 5.0).all()
    ring = camera_rig("ring8", width=320, height=240, centre=(1.0, 2.0, 1.0), radius=5.0)
    c = np.array([cam.centre for cam in ring])
    np.testing.assert_allclose(np.hypot(c[:, 0] - 1, c[:, 1] - 2), 5.0)
    az = np.unwrap(np.arctan2(c[:, 1] - 2, c[:, 0] - 1))
    np.testing.assert_allclose(np.diff(az), np.pi / 4)  # evenly spaced
    assert ring[0].shape == (240, 320)
    with pytest.raises(InputError, match=r"must be one of \['humaneva4', 'ring8'\]"):
        camera_rig("vicon12")


def test_preset_rig_round_trips_through_a_file(tmp_path):
    cams = camera_rig("humaneva4")
    write_cameras(tmp_path / "he.yml", cams)
    assert all(_same(a, b) for a, b in zip(cams, read_cameras(tmp_path / "he.yml"), strict=True))


def test_in_view_needs_every_camera():
    # A camera 3 m in front of the origin, 55° field of view (half-width at the origin
    # 3 tan 27.5° = 1.56 m), the other from the opposite side.
    K = intrinsics(640, 480, 55.0)
    front = Camera(K, *look_at([0.0, -3.0, 1.0], [0.0, 0.0, 1.0]), 640, 480, None, "front")
    back = Camera(K, *look_at([0.0, 3.0, 1.0], [0.0, 0.0, 1.0]), 640, 480, None, "back")
    X = np.array(
        [
            [0.0, 0.0, 1.0],  # centre: both see it
            [1.4, 0.0, 1.0],  # inside both images (1.4 < 1.56)
            [1.7, 0.0, 1.0],  # outside both images
            [0.0, -3.5, 1.0],
        ]
    )  # behind the front camera, seen by the back one
    np.testing.assert_array_equal(in_view(X, [front]), [True, True, False, False])
    np.testing.assert_array_equal(in_view(X, [back]), [True, True, False, True])
    np.testing.assert_array_equal(in_view(X, [front, back]), [True, True, False, False])
    assert in_view(X, []).all()  # no rig: nothing is known to be unseen


def test_in_view_is_the_projection_tested_against_the_image():
    """in_view's compiled pass gives the answer of :meth:`Camera.project` and the image's
    bounds to the bit, with and without distortion, for points behind, beside and inside
    the images."""
    rng = np.random.default_rng(7)
    cams = []
    for k, (eye, dist) in enumerate(
        [((3, 0, 1), None), ((0, -3, 1.5), (-0.2, 0.05, 0.001, -0.002, 0.01)), ((-2, 2, 1), None)]
    ):
        R, t = look_at(np.array(eye, float), np.zeros(3))
        cams.append(Camera(intrinsics(64, 48, 50), R, t, 64, 48, dist=dist, name=f"c{k}"))
    X = rng.uniform(-3, 3, size=(4000, 3))
    for cameras in (cams, cams[1:2], []):
        expected = np.ones(len(X), dtype=bool)
        for cam in cameras:
            uv, depth = cam.project(X)
            expected &= (depth > 0) & (uv[:, 0] >= 0) & (uv[:, 0] <= cam.width)
            expected &= (uv[:, 1] >= 0) & (uv[:, 1] <= cam.height)
        ok = in_view(X, cameras)
        assert np.array_equal(ok, expected)
        assert 0 < ok.sum() < len(X) or not cameras
    assert in_view(np.zeros((0, 3)), cams).shape == (0,)
