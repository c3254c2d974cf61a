"""Tests of meshmocap.io.bvh: parsing, conventions, errors, writing, and real CMU files."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from meshmocap.body.motion import Y_UP_TO_Z_UP, Motion, resample
from meshmocap.body.skeleton import Skeleton
from meshmocap.errors import FormatError, InputError, MeshmocapFileNotFoundError
from meshmocap.geometry.rotations import euler_matrix, so3_exp
from meshmocap.io.bvh import UNIT_METRES, read_bvh, write_bvh
from toys import TINY_BVH as TINY


def write(tmp_path: Path, text: str, name: str = "clip.bvh", newline: str = "\n") -> Path:
    path = tmp_path / name
    path.write_bytes(text.replace("\n", newline).encode())
    return path


def test_tiny_file_positions_by_hand(tmp_path: Path) -> None:
    m = read_bvh(write(tmp_path, TINY), unit="cm")
    assert m.skeleton.names == ("Hips", "Spine", "Leg")
    assert list(m.skeleton.parents) == [-1, 0, 0]
    assert m.fps == 25.0 and m.n_frames == 2
    # Y-up cm → Z-up m: (x, y, z) → (x, −z, y) / 100; exact arithmetic up to float rounding.
    np.testing.assert_allclose(m.skeleton.offsets[1], [0, 0, 0.10], atol=1e-15)
    np.testing.assert_allclose(m.skeleton.end_offsets[2], [0, 0, -0.40], atol=1e-15)
    # frame 1: root = OFFSET + channels = (2, 4, 6) cm;
    # Rz(90°) turns Spine's offset (0, 10, 0) into (−10, 0, 0)
    P = m.joint_positions[1]
    np.testing.assert_allclose(P[0], [0.02, -0.06, 0.04], atol=1e-12)
    np.testing.assert_allclose(P[1], [-0.08, -0.06, 0.04], atol=1e-12)


def test_rotation_channel_order_convention(tmp_path: Path) -> None:
    """Channels "A B C" with values (a, b, c) give Ra(a) @ Rb(b) @ Rc(c), for every order."""
    rng = np.random.default_rng(0)
    orders = ["ZXY", "XYZ", "YZX", "ZY"]
    text = "HIERARCHY\nROOT r\n{\nOFFSET 0 0 0\nCHANNELS 3 Zrotation Yrotation Xrotation\n"
    for k, order in enumerate(orders):
        chans = " ".join(f"{a}rotation" for a in order)
        text += f"JOINT j{k}\n{{\nOFFSET 0 1 0\nCHANNELS {len(order)} {chans}\n"
    text += "End Site\n{\nOFFSET 0 1 0\n}\n" + "}\n" * (len(orders) + 1)
    n_ch = 3 + sum(len(o) for o in orders)
    values = rng.uniform(-180, 180, size=(5, n_ch))
    rows = "\n".join(" ".join(f"{v:.6f}" for v in row) for row in values)
    text += f"MOTION\nFrames: 5\nFrame Time: 0.01\n{rows}\n"
    m = read_bvh(write(tmp_path, text), unit="m", up="z")  # up="z": no axis change
    v = np.round(values, 6)
    np.testing.assert_allclose(
        m.rotations[:, 0], euler_matrix(v[:, :3], "ZYX", degrees=True), atol=1e-12
    )
    col = 3
    for k, order in enumerate(orders):
        expected = euler_matrix(v[:, col : col + len(order)], order, degrees=True)
        np.testing.assert_allclose(m.rotations[:, k + 1], expected, atol=1e-12)
        col += len(order)


def test_whitespace_variants_parse_identically(tmp_path: Path) -> None:
    ref = read_bvh(write(tmp_path, TINY), unit="cm")
    messy = TINY.replace("  ", "\t").replace("\n", "  \n").replace("MOTION", "\nMOTION\n")
    messy = messy.replace("Frames: 2", "Frames:\t2").replace(
        "0 0 0 0 0 0 0 0 0", "0  0\t0 0 0 0 0 0 0"
    )
    for newline in ("\r\n", "\n"):
        m = read_bvh(write(tmp_path, messy + "\n\n", "messy.bvh", newline), unit="cm")
        np.testing.assert_array_equal(m.joint_positions, ref.joint_positions)
    m = read_bvh(write(tmp_path, TINY, "mac.bvh", "\r"), unit="cm")  # old Mac CR endings
    np.testing.assert_array_equal(m.joint_positions, ref.joint_positions)


def test_end_sites_and_position_channels(tmp_path: Path) -> None:
    text = """HIERARCHY
ROOT a
{
  OFFSET 0 0 0
  CHANNELS 4 Yposition Xrotation Yrotation Zrotation
  End Site
  {
    OFFSET 9 9 9
  }
  JOINT b
  {
    OFFSET 0 1 0
    CHANNELS 4 Xposition Zrotation Xrotation Yrotation
    End Site
    {
      OFFSET 0 3 0
    }
    End Site
    {
      OFFSET 0 7 0
    }
  }
  JOINT c
  {
    OFFSET 1 0 0
    CHANNELS 0
  }
}
MOTION
Frames: 2
Frame Time: 0.5
5 0 0 0 2 0 0 0
6 0 0 0 2 0 0 0
"""
    m = read_bvh(write(tmp_path, text), unit="m", up="z")
    # a non-leaf End Site is kept, the first of several wins, none gives zeros
    np.testing.assert_array_equal(m.skeleton.end_offsets, [[9, 9, 9], [0, 3, 0], [0, 0, 0]])
    np.testing.assert_array_equal(m.root_positions, [[0, 5, 0], [0, 6, 0]])
    # constant non-root position channels are added to the offset
    np.testing.assert_array_equal(m.skeleton.offsets[1], [2, 1, 0])
    animated = text.replace("6 0 0 0 2", "6 0 0 0 3")
    with pytest.raises(FormatError, match=r"anim\.bvh:13: joint 'b' has animated position"):
        read_bvh(write(tmp_path, animated, "anim.bvh"), unit="m")


def test_unit_auto_detection_synthetic(tmp_path: Path) -> None:
    """A 1.7 m tall figure is recognised in every unit (heights include End Sites)."""
    for unit, scale in UNIT_METRES.items():
        h = 1.7 / scale
        text = (
            f"HIERARCHY\nROOT r\n{{\nOFFSET 0 0 0\nCHANNELS 3 Xposition Yposition Zposition\n"
            f"JOINT top\n{{\nOFFSET 0 {h / 2:.9g} 0\nCHANNELS 0\n"
            f"End Site\n{{\nOFFSET 0 {h / 2:.9g} 0\n}}\n}}\n}}\n"
            "MOTION\nFrames: 1\nFrame Time: 1\n0 0 0\n"
        )
        m = read_bvh(write(tmp_path, text, f"{unit}.bvh"))
        assert m.skeleton.rest_positions[1, 2] + m.skeleton.end_offsets[1, 2] == pytest.approx(1.7)


def test_options_and_frame_selection(tmp_path: Path) -> None:
    path = write(tmp_path, TINY)
    with pytest.raises(InputError, match=r"unit must be one of \['auto', 'm', 'cm'"):
        read_bvh(path, unit="km")  # type: ignore[arg-type]
    with pytest.raises(InputError, match="up must be one of"):
        read_bvh(path, up="x")  # type: ignore[arg-type]
    full = read_bvh(path, unit="cm")
    one = read_bvh(path, unit="cm", frames=[1])
    np.testing.assert_array_equal(one.joint_positions[0], full.joint_positions[1])
    assert read_bvh(path, unit="cm", frames=slice(None, None, 2)).fps == 12.5
    for bad in ([5], slice(3, None), slice(None, None, -1), [[0]]):
        with pytest.raises(InputError, match="read_bvh: frame"):
            read_bvh(path, frames=bad)  # type: ignore[arg-type]


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("", r"empty file"),
        ("  \n\n", r"empty file"),
        (TINY.replace("HIERARCHY", "HIERARCHX"), r":1: expected HIERARCHY, found 'HIERARCHX'"),
        (TINY[: TINY.index("MOTION")], r"no MOTION section"),
        (
            TINY.replace("Frames: 2", "Frames: 3"),
            r":26: truncated file\? header declares 3 frames, found 2",
        ),
        (TINY.replace("Frames: 2", "Frames: 1"), r":26: header declares 1 frames, found 2"),
        (
            TINY.replace("Frames: 2", "Frames: two"),
            r":26: expected a positive frame count, found 'two'",
        ),
        (TINY.replace("Frame Time: 0.04", "Frame Time: 0"), r":27: expected a positive Frame Time"),
        (TINY.replace("Frame Time: 0.04", "Frame Tim 0.04"), r":27: expected 'Frame Time"),
        (
            TINY.replace(" 0 0 45\n", " 45\n"),
            r":29: expected 12 values per frame \(channel count\), found 10",
        ),
        (TINY.replace(" 0 0 45\n", " 0 0 4x5\n"), r":29: expected a number, found '4x5'"),
        (TINY.replace(" 0 0 45\n", " 0 0 nan\n"), r":29: non-finite value 'nan'"),
        (
            TINY.replace("Xrotation Yrotation Zrotation", "Xrotation Yrotation Wrotation"),
            r":18: unknown channel 'Wrotation'",
        ),
        (TINY.replace("CHANNELS 3 Xrot", "CHANNELS 4 Xrot"), r":19: unknown channel 'End'"),
        (
            TINY.replace("  }\n}\nMOTION", "  }\nMOTION"),
            r":3: unbalanced braces: '\{' of 'Hips' is never closed",
        ),
        (TINY.replace("}\nMOTION", "}\n}\nMOTION"), r":25: unbalanced braces: unexpected '\}'"),
        (TINY.replace("OFFSET 5 -10 0", "OFFSET 5 -10"), r":17: OFFSET expects 3 numbers"),
        (TINY.replace("    OFFSET 0 10 0\n", ""), r":6: joint 'Spine' has no OFFSET"),
        (TINY.replace("JOINT Leg", "JOINT Spine"), r":15: duplicate joint name 'Spine'"),
        (TINY.replace("}\nMOTION", "}\nROOT x\n{\nOFFSET 0 0 0\n}\nMOTION"), r":25: several ROOT"),
    ],
)
def test_format_errors_name_file_and_line(tmp_path: Path, text: str, message: str) -> None:
    path = write(tmp_path, text, "bad_clip.bvh")
    with pytest.raises(FormatError, match=message) as info:
        read_bvh(path, unit="cm")
    msg = str(info.value)
    assert "bad_clip.bvh" in msg and "\n" not in msg


def test_file_not_found(tmp_path: Path) -> None:
    with pytest.raises(MeshmocapFileNotFoundError, match=r"nothere\.bvh"):
        read_bvh(tmp_path / "nothere.bvh")
    with pytest.raises(MeshmocapFileNotFoundError, match="nofolder"):
        write_bvh(tmp_path / "nofolder" / "x.bvh", read_bvh(write(tmp_path, TINY)))


def _random_motion(seed: int = 1, T: int = 7) -> Motion:
    rng = np.random.default_rng(seed)
    sk = Skeleton(
        ("root", "a", "b", "c"), [-1, 0, 1, 0], rng.normal(size=(4, 3)), rng.normal(size=(4, 3))
    )
    return Motion(sk, so3_exp(rng.normal(size=(T, 4, 3))), rng.normal(size=(T, 3)), 30.0)


@pytest.mark.parametrize(("order", "unit"), [("ZXY", "m"), ("XYZ", "cm"), ("ZYX", "inch")])
def test_write_read_round_trip(tmp_path: Path, order: str, unit: str) -> None:
    """Joint positions survive write→read to 1e-6 m (8 written decimals: ~1e-8 m, 1e-8°)."""
    m = _random_motion()
    path = tmp_path / "rt.bvh"
    write_bvh(path, m, order=order, unit=unit)  # type: ignore[arg-type]
    back = read_bvh(path, unit=unit)  # type: ignore[arg-type]
    assert back.skeleton.names == m.skeleton.names and back.fps == m.fps
    np.testing.assert_allclose(back.joint_positions, m.joint_positions, atol=1e-6)
    np.testing.assert_allclose(
        back.skeleton.end_offsets[[2, 3]], m.skeleton.end_offsets[[2, 3]], atol=1e-7
    )
    assert [p.name for p in tmp_path.iterdir()] == ["rt.bvh"]  # no temporary file left


def test_root_positions_are_written_absolute(tmp_path: Path) -> None:
    """Root OFFSET zero and absolute position channels: readers that ignore the root's
    offset (Blender's importer) place the body where readers that add it do."""
    m = _random_motion()
    text = write_bvh(tmp_path / "r.bvh", m, unit="m", up="z").read_text().splitlines()
    assert text[3].split() == ["OFFSET", "0.00000000", "0.00000000", "0.00000000"]
    first = np.array(text[text.index("MOTION") + 3].split()[:3], dtype=float)
    np.testing.assert_allclose(first, m.root_positions[0], atol=1e-8)


def test_write_is_atomic(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    path = tmp_path / "keep.bvh"
    path.write_text("old")

    def boom(*args: object) -> None:
        raise OSError("disk full")

    monkeypatch.setattr("meshmocap.io.bvh.os.replace", boom)
    with pytest.raises(OSError, match="disk full"):
        write_bvh(path, _random_motion())
    assert path.read_text() == "old" and [p.name for p in tmp_path.iterdir()] == ["keep.bvh"]


def test_write_rejects_bad_options_and_names(tmp_path: Path) -> None:
    m = _random_motion()
    with pytest.raises(InputError, match=r"order must be one of \['XYZ'"):
        write_bvh(tmp_path / "x.bvh", m, order="XYX")  # type: ignore[arg-type]
    with pytest.raises(InputError, match="unit must be one of"):
        write_bvh(tmp_path / "x.bvh", m, unit="auto")  # type: ignore[arg-type]
    sk = Skeleton(("root", "left arm"), [-1, 0], np.ones((2, 3)))
    bad = Motion(sk, np.broadcast_to(np.eye(3), (1, 2, 3, 3)), np.zeros((1, 3)), 30.0)
    with pytest.raises(InputError, match="'left arm'"):
        write_bvh(tmp_path / "x.bvh", bad)
    assert not list(tmp_path.iterdir())


# ----------------------------------------------------------------------------- real CMU files
@pytest.fixture(scope="module")
def bvh_01(cmu: Path) -> Motion:
    return read_bvh(cmu / "01_01.bvh")


@pytest.mark.parametrize(
    ("name", "unit", "joints", "frames"),
    [
        ("01_01.bvh", "cmu", 31, 2752),
        ("07_01.bvh", "cm", 43, 317),
        ("09_01.bvh", "cm", 43, 149),
        ("16_01.bvh", "cmu", 31, 322),
    ],
)
def test_unit_auto_detection_cmu_flavours(
    cmu: Path, name: str, unit: str, joints: int, frames: int
) -> None:
    """MotionBuilder-friendly and raw amc2bvh files are in 1/0.45 inch, Daz-friendly in cm."""
    auto = read_bvh(cmu / name, frames=[0, 1])
    explicit = read_bvh(cmu / name, unit=unit, frames=[0, 1])  # type: ignore[arg-type]
    np.testing.assert_array_equal(auto.skeleton.offsets, explicit.skeleton.offsets)
    assert auto.skeleton.n_joints == joints and auto.fps == pytest.approx(
        120 if name != "16_01.bvh" else 30
    )
    assert read_bvh(cmu / name, frames=slice(-1, None)).fps == auto.fps
    height = np.ptp(auto.joint_positions[0, :, 2])
    assert 1.2 < height < 2.0  # a standing adult in metres, Z up


def test_16_01_matches_third_party_world_positions(cmu: Path) -> None:
    """FK of 16_01.bvh equals the CSV of a third-party BVH tool (raw units, Y up).

    Read with unit="m" (scale 1) so positions stay in raw units; the Z-up conversion is a
    signed permutation, undone exactly. Observed difference ~1e-14 raw units: both are
    float64 FK with the same conventions, the CSV printed with ~16 digits. Tolerance 1e-9
    raw units (6e-11 m) leaves room for a different summation order. The CSV's Time column
    (and the header's 30 fps; the data is 120 fps) is ignored.
    """
    m = read_bvh(cmu / "16_01.bvh", unit="m")
    header = (cmu / "16_01_worldpos.csv").read_text().split("\n", 1)[0].split(",")
    table = np.loadtxt(cmu / "16_01_worldpos.csv", delimiter=",", skiprows=1)
    assert table.shape == (m.n_frames, 1 + 3 * 38)
    P = m.joint_positions @ Y_UP_TO_Z_UP  # back to Y up: rows times C
    ends = P + np.einsum("tjab,jb->tja", m.global_rotations, m.skeleton.end_offsets) @ Y_UP_TO_Z_UP
    for k in range(1, len(header), 3):
        name = header[k].removesuffix(".X")
        got = (
            ends[:, m.skeleton.index(name[:-3])]
            if name.endswith("End")
            else P[:, m.skeleton.index(name)]
        )
        np.testing.assert_allclose(got, table[:, k : k + 3], rtol=0, atol=1e-9, err_msg=name)


def test_real_round_trip_and_resample(tmp_path: Path, bvh_01: Motion) -> None:
    m = bvh_01.frames(slice(0, 400))
    write_bvh(tmp_path / "01.bvh", m, unit="cm")
    back = read_bvh(tmp_path / "01.bvh")  # auto: cm
    np.testing.assert_allclose(back.joint_positions, m.joint_positions, atol=1e-6)
    # 120 → 30 fps lands on every 4th frame: slerp at u = 0, equal to float rounding
    r = resample(m, 30.0)
    assert r.fps == 30.0 and r.n_frames == 100
    np.testing.assert_allclose(r.joint_positions, m.joint_positions[::4], atol=1e-9)
    np.testing.assert_allclose(
        read_bvh(tmp_path / "01.bvh", frames=slice(0, None, 4)).joint_positions,
        r.joint_positions,
        atol=1e-6,
    )


def test_write_at_gimbal_lock(tmp_path: Path) -> None:
    """A middle angle of exactly 90° (scipy warns, we silence it) still round-trips to 1e-6 m."""
    m = _random_motion(T=3)
    R = m.rotations.copy()
    R[:, 1] = Y_UP_TO_Z_UP @ euler_matrix([30.0, 90.0, 40.0], "ZXY", degrees=True) @ Y_UP_TO_Z_UP.T
    m = Motion(m.skeleton, R, m.root_positions, m.fps)
    back = read_bvh(write_bvh(tmp_path / "lock.bvh", m, order="ZXY", unit="cm"), unit="cm")
    np.testing.assert_allclose(back.joint_positions, m.joint_positions, atol=1e-6)
