"""The first frame's pose chosen by the silhouettes' evidence
(:mod:`meshmocap.estimate.performer.first_frame`): each candidate fitted to the silhouettes
with the body held, the one leaving the smaller objective kept; without silhouettes a given
start is used as it is."""

from types import SimpleNamespace

import numpy as np
import pytest

from meshmocap.body.shape_space import load_shape_space
from meshmocap.estimate.performer.first_frame import frame_views, refined_start, start_of_frame
from meshmocap.estimate.performer.shape_fit import silhouette_view
from meshmocap.geometry.rotations import so3_exp
from meshmocap.geometry.silhouette import silhouette
from meshmocap.io.start import Start, start_json, start_of_json
from meshmocap.studio.rigs import camera_rig


@pytest.fixture(scope="module")
def scene():
    """The mean body with its arms lowered and a knee bent, seen by the four HumanEva
    cameras; its true pose, and the cameras and masks."""
    body = load_shape_space().template(np.zeros(16))
    names = body.skeleton.names
    w = np.zeros((body.skeleton.n_joints, 3))
    w[names.index("LeftArm")] = [0.0, 0.0, -0.9]
    w[names.index("RightArm")] = [0.0, 0.0, 0.9]
    w[names.index("LeftLeg")] = [0.6, 0.0, 0.0]
    R = so3_exp(w)
    root = body.skeleton.rest_positions[0] + np.array([0.05, -0.03, 0.0])
    cams = camera_rig("humaneva4")
    V = body.pose(R, root).V
    masks = [silhouette(V, body.F, c, assume_closed=True) for c in cams]
    return body, R, root, cams, masks


def _error(body, R, root, R_true, root_true) -> float:
    """Mean evaluation-joint distance, mm."""
    E = body.pose(R, root).eval_joints
    return 1000 * float(np.linalg.norm(E - body.pose(R_true, root_true).eval_joints, axis=1).mean())


@pytest.mark.slow
def test_the_candidate_that_fits_the_silhouettes_is_kept_and_brought_closer(scene):
    """A search-like start near the truth (every joint turned a little, 3 cm off) and a
    body-fit-like start with an arm turned the wrong way: the near one is kept, its joints
    brought closer to the truth by the fit (6 iterations), and both objectives recorded."""
    body, R, root, cams, masks = scene
    rng = np.random.default_rng(3)
    near = Start(0, R @ so3_exp(0.02 * rng.normal(size=(len(R), 3))), root + 0.03, "search")
    w = np.zeros((len(R), 3))
    w[body.skeleton.names.index("LeftArm")] = [0.0, 1.8, 0.0]
    far = Start(0, R @ so3_exp(w), root, "subject-fit")
    views = [silhouette_view(m, c) for m, c in zip(masks, cams, strict=True)]
    chosen = refined_start(body, views, [far, near], iterations=6)
    assert chosen.source == "search"
    before = _error(body, near.R, near.root, R, root)
    after = _error(body, chosen.R, chosen.root, R, root)
    assert before > 20 and after < 0.5 * before
    assert 0 < chosen.silhouette_cost < chosen.rival_cost
    back = start_of_json(start_json(chosen))
    assert back.silhouette_cost == chosen.silhouette_cost and back.rival_cost == chosen.rival_cost


def test_a_given_start_is_used_as_it_is_where_nothing_can_be_compared():
    """Without silhouettes (a mesh or point-cloud frame) a given start is used without a
    search; a start that is not the body fit's is used even with silhouettes, and so is one
    already chosen by the silhouettes; with neither, the search's."""
    R, root = np.tile(np.eye(3), (31, 1, 1)), np.zeros(3)
    calls = []

    def search():
        calls.append(1)
        return Start(0, R, root, "search")

    cams = camera_rig("humaneva4")
    masks = [np.zeros(c.shape, dtype=bool) for c in cams]
    for m in masks:
        m[100:300, 200:260] = True
    bare = SimpleNamespace(cameras=[], silhouettes=[])
    studio = SimpleNamespace(cameras=cams, silhouettes=masks)
    assert frame_views(bare) is None and len(frame_views(studio)) == 4
    fitted, rest = Start(0, R, root, "subject-fit"), Start(0, R, root, "subject-rest")
    assert start_of_frame(None, bare, fitted, search) is fitted and not calls
    assert start_of_frame(None, studio, rest, search) is rest and not calls
    assert start_of_frame(None, bare, None, search).source == "search" and len(calls) == 1
    # a start this function chose already (the demo's, found once for its trackers)
    chosen = Start(0, R, root, "subject-fit", silhouette_cost=1e-4, rival_cost=2e-4)
    assert start_of_frame(None, studio, chosen, search) is chosen and len(calls) == 1
