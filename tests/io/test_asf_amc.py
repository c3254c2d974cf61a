"""Tests of meshmocap.io.asf_amc: ASF skeletons, AMC decoding, errors, and real CMU trials."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import scipy.io

from meshmocap.body.motion import Y_UP_TO_Z_UP, Motion
from meshmocap.errors import FormatError, InputError, MeshmocapFileNotFoundError
from meshmocap.geometry.rotations import euler_matrix
from meshmocap.io.asf_amc import (
    AsfSkeleton,
    motion_from_channels,
    read_amc,
    read_amc_channels,
    read_asf,
)
from meshmocap.io.bvh import read_bvh, write_bvh
from toys import TINY_AMC as AMC
from toys import TINY_ASF as ASF

INCH = 0.0254


def write(tmp_path: Path, name: str, text: str, newline: str = "\n") -> Path:
    path = tmp_path / name
    path.write_bytes(text.replace("\n", newline).encode())
    return path


@pytest.fixture
def asf(tmp_path: Path) -> AsfSkeleton:
    return read_asf(write(tmp_path, "tiny.asf", ASF, "\r\n"))


def test_asf_skeleton_model(asf: AsfSkeleton) -> None:
    """Joint = bone start; offset = parent's direction × length; leaves get end offsets."""
    sk = asf.skeleton
    assert sk.names == ("root", "spine", "arm", "hip") and list(sk.parents) == [-1, 0, 1, 0]
    # inches, Y up → metres, Z up: (x, y, z) → (x, −z, y); exact up to float rounding
    np.testing.assert_allclose(sk.rest_positions[2], [0, 0, 10 * INCH], atol=1e-15)
    np.testing.assert_allclose(
        sk.end_offsets, [[0, 0, 0], [0, 0, 0], [5 * INCH, 0, 0], [0, 0, -4 * INCH]], atol=1e-15
    )
    assert asf.channel_names == (
        "root.tx",
        "root.ty",
        "root.tz",
        "root.rx",
        "root.ry",
        "root.rz",
        "spine.rx",
        "spine.ry",
        "spine.rz",
        "arm.rx",
    )
    assert asf.metres_per_unit == INCH and asf.degrees


def test_amc_by_hand(tmp_path: Path, asf: AsfSkeleton) -> None:
    path = write(tmp_path, "tiny.amc", AMC, "\r\n")
    table = read_amc_channels(path, asf)  # bones in any order within a frame
    np.testing.assert_array_equal(
        table, [[1, 2, 3, 0, 0, 0, 0, 0, 0, 0], [1, 2, 3, 0, 0, 90, 0, 0, 0, 90]]
    )
    m = read_amc(path, asf, fps=60)
    assert m.n_frames == 2 and m.fps == 60
    # frame 2: root at (1, 2, 3) in, turned Rz(90°): the spine's (0, 10, 0) becomes (−10, 0, 0);
    # arm: C = Rz(90°), M = Rx(90°) → L = C M Cᵀ = Ry(90°), so its end (5, 0, 0) → (0, 0, −5).
    to_z = np.array([[1, 0, 0], [0, 0, -1], [0, 1, 0]]) * INCH
    P = m.joint_positions[1]
    np.testing.assert_allclose(P[0], to_z @ [1, 2, 3], atol=1e-12)
    np.testing.assert_allclose(P[2], to_z @ [-9, 2, 3], atol=1e-12)
    end = P[2] + m.global_rotations[1, 2] @ m.skeleton.end_offsets[2]
    np.testing.assert_allclose(end, to_z @ [-9, 2, -2], atol=1e-12)


def test_dof_composition_convention(tmp_path: Path, asf: AsfSkeleton) -> None:
    """dof "rx ry rz" = (a, b, c) gives M = Rz(c) Ry(b) Rx(a) (fixed axes, in dof order)."""
    rng = np.random.default_rng(3)
    v = np.round(rng.uniform(-90, 90, size=(4, 6)), 4)
    frames = "".join(
        f"{k + 1}\nroot 0 0 0 {r[0]} {r[1]} {r[2]}\nspine {r[3]} {r[4]} {r[5]}\narm 0\n"
        for k, r in enumerate(v)
    )
    m = read_amc(write(tmp_path, "conv.amc", ":DEGREES\n" + frames), asf)
    R = Y_UP_TO_Z_UP.T @ m.rotations @ Y_UP_TO_Z_UP  # back to the ASF frame (Y up)
    for j, cols in ((0, slice(0, 3)), (1, slice(3, 6))):
        expected = euler_matrix(v[:, cols][:, ::-1], "ZYX", degrees=True)
        np.testing.assert_allclose(R[:, j], expected, atol=1e-12)


def test_units_radians_order_and_translation_dofs(tmp_path: Path) -> None:
    text = ASF.replace("length 1.0", "length 0.45").replace("angle deg", "angle rad")
    # child listed before its parent in :bonedata → joints in depth-first order
    text = (
        text.replace("name spine", "name TMP")
        .replace("name arm", "name spine")
        .replace("name TMP", "name arm")
    )
    text = text.replace("spine arm\n", "arm spine\n").replace("root spine hip", "root arm hip")
    a = read_asf(write(tmp_path, "r.asf", text))
    assert a.skeleton.names == ("root", "arm", "spine", "hip") and not a.degrees
    assert a.metres_per_unit == pytest.approx(INCH / 0.45)
    amc = "1\nroot 0 0 0 0 0 1.5\narm 0 0 0\nspine 0\n"
    m_rad = read_amc(write(tmp_path, "r.amc", amc), a)
    np.testing.assert_allclose(
        m_rad.rotations[0, 0],
        Y_UP_TO_Z_UP @ euler_matrix([1.5, 0, 0], "ZYX") @ Y_UP_TO_Z_UP.T,
        atol=1e-12,
    )
    m_deg = read_amc(write(tmp_path, "d.amc", ":DEGREES\n" + amc), a)  # AMC keyword wins
    np.testing.assert_allclose(
        m_deg.rotations[0, 0],
        Y_UP_TO_Z_UP @ euler_matrix([1.5, 0, 0], "ZYX", degrees=True) @ Y_UP_TO_Z_UP.T,
        atol=1e-12,
    )
    # a non-root translation dof: raw channels are fine, a Motion cannot hold it
    b = read_asf(write(tmp_path, "t.asf", ASF.replace("dof rx\n", "dof rx tx\n")))
    path = write(tmp_path, "t.amc", "1\nroot 0 0 0 0 0 0\nspine 0 0 0\narm 0 7\n")
    assert read_amc_channels(path, b)[0, -1] == 7
    with pytest.raises(FormatError, match=r"t\.amc: bone 'arm' has a 'tx' dof"):
        read_amc(path, b)


def test_frames_and_options(tmp_path: Path, asf: AsfSkeleton) -> None:
    path = write(tmp_path, "tiny.amc", AMC)
    m = read_amc(path, asf, frames=slice(1, None))
    assert m.n_frames == 1 and m.root_positions[0] == pytest.approx(
        read_amc(path, asf).root_positions[1]
    )
    assert read_amc(path, asf, frames=slice(None, None, 2)).fps == 60
    with pytest.raises(InputError, match="read_amc: frame"):
        read_amc(path, asf, frames=[2])
    with pytest.raises(InputError, match="fps must be a positive number"):
        read_amc(path, asf, fps=0)
    with pytest.raises(InputError, match="asf must be an AsfSkeleton"):
        read_amc(path, "tiny.asf")  # type: ignore[arg-type]


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("", r"empty file"),
        (":FULLY-SPECIFIED\n:DEGREES\n", r"no frames"),
        (
            AMC.replace("spine 0 0 0\narm 0", "spinex 0 0 0\narm 0"),
            r"bad\.amc:7: bone 'spinex' is not in tiny\.asf",
        ),
        (
            AMC.replace("spine 0 0 0\narm 0", "spine 0 0\narm 0"),
            r"bad\.amc:7: bone 'spine' expects 3 values \(rx ry rz\), found 2",
        ),
        (
            AMC.replace("spine 0 0 0\n", "", 1).replace("arm 90", "arm 90\nspine 0 0 0"),
            r":5: frame 1 has no values for bone 'spine'$",
        ),
        (
            AMC[: AMC.rindex("spine")],
            r":9: frame 2 has no values for bone 'spine' \(truncated file\?\)",
        ),
        (AMC.replace("arm 90", "arm 90\narm 1"), r":9: frame 2 repeats bone 'arm'"),
        (AMC.replace("arm 90", "arm 9.0.0"), r":10: expected a number, found '9\.0\.0'"),
        (
            AMC.replace("1\nroot", "1 2\nroot"),
            r":5: expected a bone name or a frame number, found '1'",
        ),
        (
            AMC.replace(":DEGREES\n1\n", ":DEGREES\n"),
            r":5: bone values before the first frame number",
        ),
    ],
)
def test_amc_errors(tmp_path: Path, asf: AsfSkeleton, text: str, message: str) -> None:
    with pytest.raises(FormatError, match=message) as info:
        read_amc(write(tmp_path, "bad.amc", text), asf)
    assert "bad.amc" in str(info.value) and "\n" not in str(info.value)


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("", r"empty file"),
        ("# only a comment\n", r"empty file"),
        ("name x\n:root\n", r":1: expected an ASF ':keyword', found 'name'"),
        (ASF.replace(":root", ":rooty"), r"no :root section"),
        (ASF.replace(":bonedata", ":bones"), r"no :bonedata section"),
        (ASF[: ASF.index(":hierarchy")], r"no :hierarchy section"),
        (ASF.replace("     length 5\n", ""), r":27: bone has no 'length'"),
        (ASF.replace("direction 1 0 0", "direction 1 0 zero"), r":30: direction expects 3 numbers"),
        (ASF.replace("axis 0 0 90 XYZ", "axis 0 0 90 XXY"), r":32: expected an axis order"),
        (ASF.replace("dof rx\n", "dof rw\n"), r":33: bad dof list 'rw'"),
        (
            ASF.replace("root spine hip", "root spine hip leg"),
            r":45: :hierarchy names unknown bone 'leg'",
        ),
        (ASF.replace("root spine hip", "root spine"), r"bones \['hip'\] are not attached to root"),
        (
            ASF.replace("spine arm\n", "spine arm\n    hip arm\n"),
            r":47: bone 'arm' has several parents",
        ),
        (ASF.replace("     name hip\n", "     name arm\n"), r":36: duplicate bone name 'arm'"),
        (
            ASF[: ASF.index("  end\n  begin\n     id 3")] + ASF[ASF.index(":hier") :],
            r":27: bone 'begin' without 'end'",
        ),
        (
            ASF.replace("(-180 180)\n  end\n", "(-180 180)\n"),
            r":35: 'begin' inside the bone begun at line 27",
        ),
        (ASF.replace("length 1.0", "length 0"), r":6: length unit must be positive"),
    ],
)
def test_asf_errors(tmp_path: Path, text: str, message: str) -> None:
    with pytest.raises(FormatError, match=message) as info:
        read_asf(write(tmp_path, "bad.asf", text))
    assert "bad.asf" in str(info.value) and "\n" not in str(info.value)


def test_files_not_found(tmp_path: Path, asf: AsfSkeleton) -> None:
    with pytest.raises(MeshmocapFileNotFoundError, match=r"nothere\.asf"):
        read_asf(tmp_path / "nothere.asf")
    with pytest.raises(MeshmocapFileNotFoundError, match=r"nothere\.amc"):
        read_amc(tmp_path / "nothere.amc", asf)


# ----------------------------------------------------------------------------- real CMU files
#: ASF bone → joint of the MotionBuilder-friendly CMU BVH (the left side; right likewise).
LEFT = {
    "lhipjoint": "LHipJoint",
    "lfemur": "LeftUpLeg",
    "ltibia": "LeftLeg",
    "lfoot": "LeftFoot",
    "ltoes": "LeftToeBase",
    "lclavicle": "LeftShoulder",
    "lhumerus": "LeftArm",
    "lradius": "LeftForeArm",
    "lwrist": "LeftHand",
    "lhand": "LeftFingerBase",
    "lfingers": "LFingers",
    "lthumb": "LThumb",
}
BONE_TO_BVH = {
    "root": "Hips",
    "lowerback": "LowerBack",
    "upperback": "Spine",
    "thorax": "Spine1",
    "lowerneck": "Neck",
    "upperneck": "Neck1",
    "head": "Head",
    **LEFT,
    **{
        "r" + k[1:]: v.replace("Left", "Right") if v.startswith("Left") else "R" + v[1:]
        for k, v in LEFT.items()
    },
}


@pytest.fixture(scope="module")
def trial_01(cmu: Path) -> tuple[AsfSkeleton, Motion, Motion]:
    asf = read_asf(cmu / "01.asf")
    return asf, read_amc(cmu / "01_01.amc", asf), read_bvh(cmu / "01_01.bvh")


def test_01_01_amc_matches_bvh(trial_01: tuple[AsfSkeleton, Motion, Motion]) -> None:
    """01_01.amc and 01_01.bvh are the same trial.

    Alignment: the BVH has 2752 frames, the AMC 2751; BVH frame 0 is the converter's T-pose
    and BVH frame k + 1 is AMC frame k. Units: the BVH is in ASF units (1/0.45 inch).
    The converter's skeleton drops two ASF bone lengths (thorax: Neck and the shoulders sit
    at Spine1; lwrist/rwrist: *FingerBase sits at *Hand), so joint positions above the
    thorax differ by 12–21 cm although the motion is the same. Hence three checks:
    positions of the joints whose chains are identical, global rotations of all 31 joints,
    and the BVH's rotations played on the ASF skeleton against the AMC. Observed maxima
    ~5e-6 (m and rotation-matrix entries), from the 4–6 printed digits of both files;
    tolerances 1e-4 (the brief's 1 cm would hide a wrong axis or dof convention on short
    bones).
    """
    asf, amc, bvh = trial_01
    assert (amc.n_frames, bvh.n_frames) == (2751, 2752) and bvh.fps == 120
    bones = list(BONE_TO_BVH)
    assert sorted(BONE_TO_BVH.values()) == sorted(bvh.skeleton.names) and sorted(bones) == sorted(
        asf.skeleton.names
    )
    ja = [asf.skeleton.index(b) for b in bones]
    jb = [bvh.skeleton.index(BONE_TO_BVH[b]) for b in bones]
    same_chain = [
        k
        for k, b in enumerate(bones)
        if b in ("root", "lowerback", "upperback", "thorax")
        or "hip" in b
        or b[1:] in ("femur", "tibia", "foot", "toes")
    ]
    Pa, Pb = amc.joint_positions[:, ja], bvh.joint_positions[1:, jb]
    assert np.abs(Pa[:, same_chain] - Pb[:, same_chain]).max() < 1e-4
    assert np.abs(amc.global_rotations[:, ja] - bvh.global_rotations[1:, jb]).max() < 1e-4
    R = np.empty((bvh.n_frames - 1, len(bones), 3, 3))
    R[:, ja] = bvh.rotations[1:, jb]
    replay = Motion(asf.skeleton, R, bvh.root_positions[1:], bvh.fps)
    assert np.abs(replay.joint_positions - amc.joint_positions).max() < 1e-4
    # the T-pose frame is not an AMC frame: it is off by decimetres
    assert np.abs(bvh.joint_positions[0, jb] - amc.joint_positions[0, ja]).max() > 0.1


def test_cmu35_mat_rows_equal_amc(cmu: Path) -> None:
    """Rows 0–89 of the .mat's Y are 35_01.amc[0::4], exactly (same decimals, same doubles)."""
    asf = read_asf(cmu / "35.asf")
    Y = scipy.io.loadmat(cmu / "cmu35WalkJog.mat")["Y"]
    table = read_amc_channels(cmu / "35_01.amc", asf)
    assert Y.shape == (2644, 62) and asf.n_channels == 62 and table.shape == (358, 62)
    np.testing.assert_array_equal(table[0::4], Y[:90])


@pytest.mark.parametrize(("subject", "trial"), [("05", "05_01"), ("49", "49_18")])
def test_other_subjects_decode(cmu: Path, subject: str, trial: str) -> None:
    asf = read_asf(cmu / f"{subject}.asf")
    m = read_amc(cmu / f"{trial}.amc", asf, frames=slice(0, None, 10))
    assert m.skeleton.n_joints == 31 and m.fps == 12
    height = np.ptp(m.joint_positions[0, :, 2])
    assert 1.2 < height < 2.0  # a standing adult, metres, Z up


def test_amc_motion_through_bvh(
    tmp_path: Path, trial_01: tuple[AsfSkeleton, Motion, Motion]
) -> None:
    """An ASF/AMC motion written as BVH reads back to 1e-6 m (8 written decimals)."""
    amc = trial_01[1].frames(slice(0, 200))
    write_bvh(tmp_path / "01.bvh", amc, unit="cm")
    back = read_bvh(tmp_path / "01.bvh")
    assert back.skeleton.names == amc.skeleton.names
    np.testing.assert_allclose(back.joint_positions, amc.joint_positions, atol=1e-6)


def test_motion_from_channels_decodes_the_mat_rows(cmu):
    """cmu35WalkJog.mat rows are raw AMC channels: decoding rows 0–89 gives exactly the
    motion of 35_01.amc[0::4] (the same numbers through the same decoder)."""
    asf = read_asf(cmu / "35.asf")
    Y = scipy.io.loadmat(cmu / "cmu35WalkJog.mat")["Y"]
    m = motion_from_channels(Y[:90], asf, fps=30.0)
    a = read_amc(cmu / "35_01.amc", asf, frames=slice(0, None, 4))
    assert m.fps == a.fps == 30.0
    assert np.array_equal(m.joint_positions, a.joint_positions[:90])
    with pytest.raises(InputError, match="expected"):
        motion_from_channels(Y[:5, :10], asf)
