"""The keyframe search: a whole-body search helped by the tracked pose (its heading, its
limbs that are not lost), cheap enough to run at many frames."""

import numpy as np
import pytest

from meshmocap.body.pose_library import load_pose_library
from meshmocap.body.template import load_template
from meshmocap.errors import InputError
from meshmocap.estimate.pose.keyframe import keyframe_pose, near_heading, nearest_library_poses
from meshmocap.estimate.pose.library import library_poses
from meshmocap.estimate.pose.pose_search import turned_about_z
from meshmocap.geometry.rotations import so3_exp
from toys import observed_frame

HELD = "13_32"  # the library trial the performer's pose comes from, kept out of the search


@pytest.fixture(scope="module")
def scene():
    """neutral_5k in a pose of library trial 13_32 (everyday), turned 2.3 rad and moved;
    the tracked pose as a track that lost the left arm holds it (the arm turned 80°, the
    heading 8° off, the root 2 cm off): the template, the pose, the frame, the tracked pose."""
    t = load_template("neutral_5k")
    lib = load_pose_library()
    i = int(np.flatnonzero(lib.trials == HELD)[3])
    R = turned_about_z(lib.on(t)[i].copy(), 2.3)
    root = np.array([0.7, -0.4, 0.95])
    posed = t.pose(R, root)
    wrong = turned_about_z(R, np.deg2rad(8.0))
    arm = t.skeleton.index("LeftArm")
    wrong[arm] = so3_exp(np.array([np.deg2rad(80.0), 0.0, 0.0])) @ wrong[arm]
    return t, R, root, posed, observed_frame(posed.V, t.F), (wrong, root + [0.02, 0.0, 0.0])


def test_the_tracked_torso_gives_the_heading_and_its_limbs_the_nearest_library_poses(scene):
    t = scene[0]
    poses = library_poses(t, exclude_trials=(HELD,))
    # the library faces heading 0; a pose turned by h faces h
    for k in (0, 10, 500):
        assert near_heading(t, turned_about_z(poses.R[k], 1.1)) == pytest.approx(1.1, abs=1e-9)
    # a library pose is its own nearest, whatever its lost limb holds
    k = 777
    Rk = poses.R[k].copy()
    Rk[t.skeleton.index("LeftArm")] = np.eye(3)
    near = nearest_library_poses(t, poses, turned_about_z(Rk, 0.4), lost=("left_arm",), n=5)
    assert k in near and len(near) == 5
    # every limb lost: nothing narrows the library (its first, diverse poses)
    everything = ("left_arm", "right_arm", "left_leg", "right_leg")
    assert nearest_library_poses(t, poses, Rk, lost=everything, n=4).tolist() == [0, 1, 2, 3]


def test_the_search_refuses_a_wrong_limb_or_pose_in_one_line(scene):
    t, _, _, _, frame, near = scene
    with pytest.raises(InputError, match="lost limbs must be among"):
        keyframe_pose(t, frame, near=near, lost=("left_wing",))
    with pytest.raises(InputError, match="near must be"):
        keyframe_pose(t, frame, near=(near[0][:3], near[1]), lost=("left_arm",))


def test_a_lost_torso_drops_the_tracked_heading_and_a_lost_head_is_no_limb(scene, monkeypatch):
    # the lost rule's parts are taken as they come (the stages stubbed: what they are given)
    from meshmocap.estimate.pose import keyframe

    t, _, _, _, frame, near = scene
    seen = {}

    def coarse(*args, headings=None, **kwargs):
        seen.setdefault("headings", []).append(headings)
        return []

    def refined(*args, limbs=(), **kwargs):
        seen["limbs"] = limbs
        return "result"

    monkeypatch.setattr(keyframe, "coarse_candidates", coarse)
    monkeypatch.setattr(keyframe, "refined_search", refined)
    monkeypatch.setattr(keyframe, "_hybrids", lambda *a: [])
    assert keyframe_pose(t, frame, near=near, lost=("head", "left_arm")) == "result"
    assert seen["limbs"] == ("left_arm",) and len(seen["headings"][-1]) == 7  # about near's
    keyframe_pose(t, frame, near=near, lost=("torso", "left_arm"))
    assert seen["headings"][-1] is None and len(seen["limbs"]) == 4  # all around, every limb


@pytest.mark.slow
def test_the_lost_arm_is_found_again_from_the_tracked_pose(scene):
    # ~3 s: headings about the tracked one, the library narrowed by the kept limbs
    t, _, _, posed, frame, near = scene
    k = t.eval_skeleton.names.index("left_wrist")
    assert np.linalg.norm(t.pose(*near).eval_joints[k] - posed.eval_joints[k]) > 0.3
    res = keyframe_pose(t, frame, near=near, lost=("left_arm",), exclude_trials=(HELD,))
    err = np.linalg.norm(t.pose(res.R, res.root).eval_joints - posed.eval_joints, axis=1)
    assert err.mean() < 0.02 and err.max() < 0.06
    assert res.lost == ()
