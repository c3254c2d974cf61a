"""The bundled CMU pose library, the ``library`` pose source and the quads' own skinning."""

from __future__ import annotations

import numpy as np
import pytest

from meshmocap.body.pose_library import LIBRARY_FORMAT, load_pose_library
from meshmocap.body.template import load_template
from meshmocap.errors import FormatError, InputError
from meshmocap.io.clips import load_clip
from meshmocap.trackers.cage.oqr import build_oqr, configuration_vector, quads_from_pose
from meshmocap.trackers.cage.surface import SkinnedSurface
from meshmocap.trackers.cage.training_poses import library_poses, load_pose_source

HELD_OUT = {"05_03", "60_01", "61_01"}  # measure generalisation: they must train nothing
EVALUATION = {"05_01", "09_01", "01_01", "49_18", "16_01", "07_01"}  # the benchmarks' clips


def test_the_library_is_diverse_in_farthest_point_order_and_holds_out_its_test_trials():
    lib = load_pose_library()
    assert len(lib) == 2400 and lib.rotations.shape == (2400, 31, 3, 3)
    assert set(lib.held_out) == HELD_OUT
    assert not (set(lib.trials) & (HELD_OUT | EVALUATION))
    assert len(set(lib.categories)) >= 6 and len(set(lib.trials)) >= 60
    # farthest-point order: each pick is no farther than the one before (to float32)
    assert np.all(np.diff(lib.radius[1:]) <= 1e-6)
    R = lib.rotations
    np.testing.assert_allclose(
        R @ np.swapaxes(R, -1, -2), np.broadcast_to(np.eye(3), R.shape), atol=1e-4
    )
    assert np.all(np.linalg.det(R) > 0.999)
    assert len(lib.digest) == 16 and load_pose_library() is lib  # cached


def test_a_file_in_another_format_is_refused(tmp_path):
    p = tmp_path / "lib.npz"
    q = np.zeros((2, 31, 4), dtype=np.int16)
    q[..., 3] = 32767
    np.savez(p, format="other", skeleton="neutral", joint_names=np.array(["a"] * 31), quaternions=q)
    with pytest.raises(FormatError, match="expected format"):
        load_pose_library(p)
    np.savez(
        p,
        format=LIBRARY_FORMAT,
        skeleton="neutral",
        joint_names=np.array(["a"] * 31),
        quaternions=q,
    )
    with pytest.raises(FormatError, match="corrupt pose library"):
        load_pose_library(p)  # no categories, trials…


def test_library_source_gives_the_first_poses_with_categories_as_groups():
    t = load_template("neutral_5k")
    ps = load_pose_source("library:30", t)
    assert ps.configurations.shape == (30, 180) and ps.template_name == "neutral_5k"
    lib = load_pose_library()
    assert list(ps.groups) == list(lib.categories[:30])
    np.testing.assert_array_equal(ps.configurations, library_poses(t, 30).configurations)
    with pytest.raises(InputError, match="library:N"):
        load_pose_source("library:0", t)


def test_the_quads_own_skinning_reproduces_the_skinned_template():
    """On library poses, the template posed from the quads (:class:`SkinnedSurface`) is the
    template posed by its skeleton: to 1e-6 m at the vertices skinned to quad joints only,
    within 20 mm at every vertex the quads place (a quad-less Neck1 or Spine1 that bends
    on its own in the source is only approximated from its neighbours)."""
    t = load_template("neutral_5k")
    oqr = build_oqr(t)
    R = load_pose_library().on(t, 12)
    root = np.tile([0.1, -0.2, 0.95], (12, 1))
    c, Q = quads_from_pose(oqr, t, R, root)
    Y = configuration_vector(c, Q)
    s = SkinnedSurface(oqr, t, np.arange(len(t.V)))
    # the fingers' vertices (no quad follows them; a fifth of this mesh's) leave the data term
    part = np.asarray(t.weights.argmax(axis=1)).ravel()
    hands = [
        j for j, n in enumerate(t.skeleton.names) if "Hand" in n or "Thumb" in n or "Finger" in n
    ]
    assert 0.7 < s.fitted.mean() < 1.0 and np.isin(part[~s.fitted], hands).all()
    for k in range(len(R)):
        V = s.points(Y[k], Q[k, 0], c[k, 0])
        err = np.linalg.norm(V - t.pose(R[k], root[k]).V, axis=1)
        assert err[s.exact].max() < 1e-6, (k, err[s.exact].max())
        assert err[s.fitted].max() < 0.02, (k, err[s.fitted].max())


def test_a_clip_with_a_wrong_header_rate_takes_its_true_one(cmu):
    m = load_clip(cmu / "16_01.bvh")
    fixed = load_clip(cmu / "16_01.bvh", source_fps=120.0)
    assert fixed.fps == 120.0 and fixed.n_frames == m.n_frames
    assert load_clip(cmu / "16_01.bvh", source_fps=120.0, fps=60.0).n_frames in (
        (m.n_frames + 1) // 2,
        m.n_frames // 2,
    )
    with pytest.raises(InputError, match="source_fps"):
        load_clip(cmu / "16_01.bvh", source_fps=0.0)
