"""Retargeting mocap clips onto the bundled template (real CMU data where available)."""

import numpy as np
import pytest

from meshmocap.body.contact import foot_heights
from meshmocap.body.motion import Motion
from meshmocap.body.retarget import KEEP_REST, floor_offsets, retarget
from meshmocap.body.template import load_template
from meshmocap.errors import InputError, SkeletonError
from meshmocap.geometry.rotations import so3_exp
from meshmocap.io.asf_amc import read_amc, read_asf
from meshmocap.io.bvh import read_bvh
from toys import toy_skeleton

RNG = np.random.default_rng(5)


@pytest.fixture(scope="module")
def neutral():
    return load_template("neutral")


def _bone_angles(src: Motion, dst: Motion, pairs: dict[str, str]) -> np.ndarray:
    """Angle (degrees) between each mapped bone's world direction in source and target."""
    out = []
    for t_name, s_name in pairs.items():
        ts, ss = dst.skeleton, src.skeleton
        j, s = ts.index(t_name), ss.index(s_name)
        if (
            np.linalg.norm(ts.bone_directions[j]) < 0.5
            or np.linalg.norm(ss.bone_directions[s]) < 0.5
        ):
            continue
        a = np.einsum("tab,b->ta", dst.global_rotations[:, j], ts.bone_directions[j])
        b = np.einsum("tab,b->ta", src.global_rotations[:, s], ss.bone_directions[s])
        out.append(np.degrees(np.arccos(np.clip(np.sum(a * b, axis=1), -1, 1))))
    return np.stack(out, axis=1)


def test_random_poses_transfer_every_bone_direction(neutral):
    """Retargeting between two different rest poses keeps each bone's world direction."""
    src_sk = toy_skeleton()  # T-pose, the template is in an A-pose
    R = so3_exp(RNG.normal(size=(6, src_sk.n_joints, 3)) * 0.6)
    src = Motion(src_sk, R, RNG.normal(size=(6, 3)), 30.0)
    out = retarget(src, neutral, floor="none", keep_rest=())
    pairs = {n: n for n in src_sk.names if n != "Hips"}
    # exact by construction up to float rounding
    assert _bone_angles(src, out, pairs).max() < 1e-4  # degrees; arccos near 1 amplifies rounding
    # by default the structural bones keep the template's shape; every other bone still
    # follows its source bone exactly
    default = retarget(src, neutral, floor="none")
    free = {n: n for n in pairs if n not in KEEP_REST}
    assert _bone_angles(src, default, free).max() < 1e-4
    # the root keeps its orientation and its (scaled) trajectory
    assert np.allclose(out.global_rotations[:, 0], src.global_rotations[:, 0], atol=1e-12)
    ratio = out.root_positions / src.root_positions
    assert np.allclose(ratio, ratio[0, 0], rtol=1e-12)


def test_structural_bones_keep_the_templates_rest_shape(neutral):
    """In the source's rest pose the hips, chest and clavicles of the template stay where
    its rest skeleton has them (local rotation identity), though the toy's T-pose bones
    point elsewhere; a source clavicle shrug still moves the template's clavicle."""
    src_sk = toy_skeleton()
    R = np.tile(np.eye(3), (2, src_sk.n_joints, 1, 1))
    shrug = so3_exp(np.array([0.0, 0.3, 0.0]))
    R[1, src_sk.index("LeftShoulder")] = shrug
    out = retarget(Motion(src_sk, R, np.zeros((2, 3)), 30.0), neutral, floor="none")
    keep = [neutral.skeleton.index(n) for n in KEEP_REST]
    assert np.allclose(out.rotations[0, keep], np.eye(3), atol=1e-12)
    j = neutral.skeleton.index("LeftShoulder")
    # the same rotation, expressed in the frame the template's chest has in the rest pose
    C = out.global_rotations[0, neutral.skeleton.parents[j]]
    assert np.allclose(out.rotations[1, j], C.T @ shrug @ C, atol=1e-12)


def test_bad_maps_and_options_are_rejected(neutral):
    src = Motion(toy_skeleton(), np.tile(np.eye(3), (1, 31, 1, 1)), np.zeros((1, 3)), 30.0)
    with pytest.raises(SkeletonError, match="'Nope'"):
        retarget(src, neutral, joint_map={"Nope": "Hips"})
    with pytest.raises(SkeletonError, match="do not map target joints"):
        retarget(src, neutral, joint_map={"Hips": "Hips"})
    with pytest.raises(InputError, match="floor must be one of"):
        retarget(src, neutral, floor="ground")


def test_floor_offsets_follow_slow_drift_but_not_jumps():
    fps = 60.0
    t = np.arange(600) / fps
    drift = 0.02 * t / t[-1]  # a 2 cm tilt of the source floor over 10 s
    jumps = np.where((t % 1.0) < 0.3, 0.2, 0.0)  # 30 % of each second in the air
    off = floor_offsets(drift + jumps, fps)
    assert np.abs(off - drift)[120:-120].max() < 2e-3  # follows the drift to 2 mm
    assert np.ptp(floor_offsets(drift + jumps, fps, constant=True)) == 0.0


def test_35_01_walk_keeps_both_feet_on_the_floor(cmu, neutral):
    src = read_amc(cmu / "35_01.amc", read_asf(cmu / "35.asf"))
    out = retarget(src, neutral)
    h = foot_heights(out, neutral)  # (T, 2) lowest skinned point of each foot, metres
    # the claim: both feet within 3 cm of the floor at their lowest points
    assert np.all(np.abs(h.min(axis=0)) < 0.03)
    # and at every frame of a walk one foot is on the floor (within 3 cm)
    assert np.all(np.abs(h.min(axis=1)) < 0.03)
    # no flipped limbs: every mapped bone points where its source bone points
    pairs = {
        "LeftUpLeg": "lfemur",
        "LeftLeg": "ltibia",
        "RightLeg": "rtibia",
        "LeftArm": "lhumerus",
        "RightForeArm": "rradius",
        "Head": "head",
    }
    assert _bone_angles(src, out, pairs).max() < 1e-4  # degrees; arccos near 1 amplifies rounding


def test_35_01_walk_slides_no_more_than_the_source(cmu, neutral):
    src = read_amc(cmu / "35_01.amc", read_asf(cmu / "35.asf"))
    out = retarget(src, neutral)
    scale = np.linalg.norm(out.root_positions[-1] - out.root_positions[0]) / np.linalg.norm(
        src.root_positions[-1] - src.root_positions[0]
    )
    h = foot_heights(out, neutral)
    for side, s_name, t_name in ((0, "lfoot", "LeftFoot"), (1, "rfoot", "RightFoot")):
        stance = h[1:, side] < 0.02
        v_t = np.linalg.norm(
            np.diff(out.joint_positions[:, out.skeleton.index(t_name), :2], axis=0), axis=1
        )
        v_s = np.linalg.norm(
            np.diff(src.joint_positions[:, src.skeleton.index(s_name), :2], axis=0), axis=1
        )
        # Ankle speed in stance, m/s: the target's is the source's scaled by the leg ratio
        # (1 mm/frame of slack for the different foot geometry).
        assert v_t[stance].mean() <= scale * v_s[stance].mean() + 1e-3


@pytest.mark.parametrize(("clip", "skip"), [("01_01.amc", 0), ("01_01.bvh", 1), ("07_01.bvh", 1)])
def test_all_three_cmu_forms_retarget(cmu, neutral, clip, skip):
    if clip.endswith(".amc"):
        src = read_amc(cmu / clip, read_asf(cmu / "01.asf"))
    else:
        src = read_bvh(cmu / clip)
    src = src.frames(slice(skip, 600))  # the BVHs start with a converter T-pose
    out = retarget(src, neutral)
    assert out.n_frames == src.n_frames and np.isfinite(out.rotations).all()
    h = foot_heights(out, neutral).min(axis=1)
    assert np.percentile(h, 10) == pytest.approx(0.0, abs=0.02)  # feet reach the floor


def test_amc_and_bvh_of_one_trial_retarget_alike(cmu, neutral):
    """01_01 as AMC and as BVH: same motion, but the BVH converter dropped the thorax and
    wrist lengths, so bone directions of the upper body differ slightly at rest."""
    a = retarget(
        read_amc(cmu / "01_01.amc", read_asf(cmu / "01.asf"), frames=slice(0, 600)), neutral
    )
    b = retarget(read_bvh(cmu / "01_01.bvh", frames=slice(1, 601)), neutral)
    d = np.linalg.norm(a.joint_positions - b.joint_positions, axis=-1)
    legs = [
        neutral.skeleton.index(n) for n in ("Hips", "LeftUpLeg", "LeftLeg", "LeftFoot", "RightFoot")
    ]
    assert d[:, legs].max() < 1e-3  # identical leg chains: sub-millimetre
    assert d.mean() < 0.01 and d.max() < 0.04  # upper body within the converter's changes
