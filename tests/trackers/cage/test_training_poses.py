"""Training poses of the pose manifold: procedural, mocap (.amc/.bvh/.mat) and hand-labelled."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import scipy.io

from meshmocap.body.motion import Motion
from meshmocap.body.procedural import walk
from meshmocap.body.retarget import retarget
from meshmocap.body.template import load_template
from meshmocap.errors import FormatError, InputError, MeshmocapFileNotFoundError
from meshmocap.geometry.rotations import so3_exp
from meshmocap.io.asf_amc import read_amc, read_asf
from meshmocap.trackers.cage.oqr import build_oqr, configuration_vector, quads_from_pose
from meshmocap.trackers.cage.training_poses import (
    CMU35_TRIALS,
    PoseSet,
    load_pose_source,
    load_pose_sources,
    poses_from_motion,
    read_mat_trials,
    read_poses,
    save_poses,
)

RNG = np.random.default_rng(7)


@pytest.fixture(scope="module")
def rig():
    t = load_template("neutral_5k")
    return t, build_oqr(t)


def test_procedural_source_maps_quads_rigidly_relative_to_the_pelvis(rig):
    t, oqr = rig
    p = load_pose_source("walk", t, oqr=oqr, duration=1.0, fps=10.0)
    assert p.configurations.shape == (11, 180) and len(p) == 11
    assert set(p.trials) == {"walk"} and set(p.groups) == {"walk"} and p.template_name == t.name
    m = walk(t, duration=1.0, fps=10.0)
    c, Q = quads_from_pose(oqr, t, m.rotations, m.root_positions)
    np.testing.assert_array_equal(p.configurations, configuration_vector(c, Q))
    # pelvis-relative: moving the root and turning the whole body changes nothing (1e-12)
    turn = so3_exp(np.array([0.0, 0.0, 0.7]))
    R = m.rotations.copy()
    R[:, 0] = turn @ R[:, 0]
    moved = Motion(m.skeleton, R, m.root_positions @ turn.T + [3.0, -2.0, 0.5], m.fps)
    again = poses_from_motion(moved, t, oqr=oqr, trial="walk")
    np.testing.assert_allclose(again.configurations, p.configurations, atol=1e-12)


def test_subsample_and_concatenate(rig):
    t, oqr = rig
    both = load_pose_sources(["walk", "jog"], t, oqr=oqr, duration=1.0, fps=10.0)
    assert len(both) == 22 and list(both.groups[[0, 11]]) == ["walk", "jog"]
    assert len(both.sources) == 2
    sub = both.subsample(5)
    assert len(sub) == 5 and list(sub.trials[[0, -1]]) == ["walk", "jog"]  # both ends kept
    np.testing.assert_array_equal(sub.configurations[-1], both.configurations[-1])
    assert len(both.subsample(100)) == 22
    with pytest.raises(InputError, match="positive int"):
        both.subsample(0)
    other = PoseSet(both.configurations, both.trials, both.groups, "heavy_male", ("x",))
    with pytest.raises(InputError, match="different templates"):
        PoseSet.concatenate([both, other])


def test_hand_labelled_quads_round_trip(rig, tmp_path):
    t, oqr = rig
    m = walk(t, duration=0.5, fps=10.0)
    c, Q = quads_from_pose(oqr, t, m.rotations, m.root_positions)
    path = save_poses(
        tmp_path / "quads.npz",
        centres=c,
        rotations=Q,
        labels=[f"pose{k}" for k in range(len(c))],
        template=t.name,
    )
    p = read_poses(path, t, oqr=oqr)
    np.testing.assert_allclose(p.configurations, configuration_vector(c, Q), atol=1e-15)
    assert list(p.trials[:2]) == ["pose0", "pose1"] and set(p.groups) == {"quads"}
    # the same file through the dispatcher
    np.testing.assert_array_equal(
        load_pose_source(path, t, oqr=oqr).configurations, p.configurations
    )


def test_hand_labelled_joint_rotations_axis_angle_and_matrices(rig, tmp_path):
    t, oqr = rig
    names = ["LeftUpLeg", "LeftLeg", "RightArm", "Spine"]
    w = 0.4 * RNG.standard_normal((3, len(names), 3))  # radians
    full = np.tile(np.eye(3), (3, t.skeleton.n_joints, 1, 1))
    full[:, [t.skeleton.index(n) for n in names]] = so3_exp(w)
    motion = Motion(t.skeleton, full, np.zeros((3, 3)), 1.0)
    want = poses_from_motion(motion, t, oqr=oqr).configurations
    for rot in (w, so3_exp(w)):
        path = save_poses(tmp_path / "joints.npz", joint_names=names, joint_rotations=rot)
        p = read_poses(path, t, oqr=oqr)
        np.testing.assert_allclose(p.configurations, want, atol=1e-12)
        assert list(p.trials) == ["joints:0", "joints:1", "joints:2"]


def test_pose_file_errors_name_the_file_in_one_line(rig, tmp_path):
    t, oqr = rig
    c, Q = quads_from_pose(
        oqr, t, np.tile(np.eye(3), (2, t.skeleton.n_joints, 1, 1)), np.zeros((2, 3))
    )
    cases = [
        (dict(centres=c, rotations=Q, template="heavy_male"), "labelled on template"),
        (dict(centres=c, rotations=2 * Q), "must be rotation matrices"),
        (dict(centres=c[:, :5], rotations=Q[:, :5]), "centres must be"),
        (dict(joint_names=["Nope"], joint_rotations=np.zeros((2, 1, 3))), "found \\['Nope'\\]"),
        (dict(centres=c, rotations=Q, labels=["a"]), "labels must have shape"),
    ]
    for k, (kwargs, match) in enumerate(cases):
        path = save_poses(tmp_path / f"bad{k}.npz", **kwargs)
        with pytest.raises(FormatError, match=match) as info:
            read_poses(path, t, oqr=oqr)
        assert str(path) in str(info.value) and "\n" not in str(info.value)
    np.savez(tmp_path / "other.npz", centres=c)
    with pytest.raises(FormatError, match="expected format 'meshmocap-poses-1'"):
        read_poses(tmp_path / "other.npz", t, oqr=oqr)
    with pytest.raises(InputError, match="either centres"):
        save_poses(tmp_path / "x.npz")
    with pytest.raises(MeshmocapFileNotFoundError, match="does not exist"):
        load_pose_source(tmp_path / "missing.bvh", t, oqr=oqr)
    with pytest.raises(InputError, match="expected one of"):
        load_pose_source("walkk", t, oqr=oqr)
    with pytest.raises(InputError, match="none given"):
        load_pose_sources([], t, oqr=oqr)


# ------------------------------------------------------------------------------ real data
@pytest.fixture(scope="module")
def mat(cmu: Path) -> Path:
    path = cmu / "cmu35WalkJog.mat"
    if not path.is_file():
        pytest.skip(f"{path} is absent")
    return path


def test_cmu35_mat_splits_into_its_31_named_trials(mat, cmu, rig):
    t, oqr = rig
    trials = read_mat_trials(mat)
    assert [(n, g) for n, g, _ in trials] == list(CMU35_TRIALS)
    counts = {n: m.n_frames for n, _, m in trials}
    assert sum(counts.values()) == 2644 and counts["35_01"] == 90
    # jogs are the short trials (35–42 rows at 30 Hz), walks 90–114 rows
    assert all(35 <= counts[n] <= 42 for n, g in CMU35_TRIALS if g == "jog")
    assert all(90 <= counts[n] <= 114 for n, g in CMU35_TRIALS if g == "walk")
    # trial 35_01 is 35_01.amc[0::4] exactly, so its poses are those of the AMC file
    amc = read_amc(cmu / "35_01.amc", read_asf(cmu / "35.asf"), frames=slice(0, None, 4))
    p = load_pose_source(mat, t, oqr=oqr)
    assert len(p) == 2644 and set(p.groups) == {"walk", "jog"}
    want = poses_from_motion(retarget(amc, t, floor="none"), t, oqr=oqr).configurations
    np.testing.assert_array_equal(p.configurations[p.trials == "35_01"], want)
    test = read_mat_trials(mat, test=True)
    assert [(n, g, m.n_frames) for n, g, m in test] == [
        ("35_18", "jog", 44),
        ("35_29", "walk", 125),
    ]


def test_other_mat_tables_bvh_and_amc_sources(mat, cmu, rig, tmp_path):
    t, oqr = rig
    Y = scipy.io.loadmat(mat)["Y"][:30]
    lbls = np.zeros((30, 2))
    lbls[:12, 0] = lbls[12:, 1] = 1
    scipy.io.savemat(tmp_path / "mine.mat", {"Y": Y, "lbls": lbls})
    with pytest.raises(MeshmocapFileNotFoundError, match="pass asf=PATH"):
        read_mat_trials(tmp_path / "mine.mat")
    p = load_pose_source(tmp_path / "mine.mat", t, oqr=oqr, asf=cmu / "35.asf")
    assert len(p) == 30 and list(np.unique(p.trials)) == ["mine#0", "mine#1"]
    scipy.io.savemat(tmp_path / "bad.mat", {"X": Y})
    with pytest.raises(FormatError, match="expected a channel table 'Y'"):
        read_mat_trials(tmp_path / "bad.mat", asf=cmu / "35.asf")
    amc = load_pose_source(cmu / "35_01.amc", t, oqr=oqr)
    assert len(amc) == 358 and set(amc.trials) == {"35_01"}
    np.testing.assert_allclose(amc.configurations[0:48:4], p.configurations[:12], atol=1e-12)
    bvh = load_pose_source(cmu / "09_01.bvh", t, oqr=oqr)
    assert len(bvh) > 100 and np.isfinite(bvh.configurations).all()
