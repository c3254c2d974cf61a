"""Nearest vertices re-used across iterations equal a new k-d query every time."""

import numpy as np
import pytest
from pykdtree.kdtree import KDTree

from meshmocap.body.template import load_template
from meshmocap.geometry.rotations import so3_exp
from meshmocap.trackers.patch.model import build_patch_model
from meshmocap.trackers.patch.nearest import NearestPoints, NearestVertices, morton_codes


@pytest.mark.parametrize("ordered", [False, True])
@pytest.mark.parametrize("scale", [0.0005, 0.005, 0.03])
def test_reranked_candidates_equal_a_new_query(scale, ordered):
    """Patches turned and moved at random (steps of ``scale`` metres and ``10 · scale``
    radians, as in a frame's Gauss–Newton iterations): every call returns the k-d query's
    neighbours, in its order, and its distances to rounding, while re-using candidates
    for some points (small steps: most); the same with each patch's vertices in compact
    chunks (``ordered``: by their Morton code at rest, as the tracker orders them)."""
    rng = np.random.default_rng(7)
    t = load_template("neutral_5k")
    m = build_patch_model(t, n_patches=80, seed=2)
    Y = m.V0[rng.choice(len(m.V0), 1500, replace=False)] + rng.normal(scale=0.01, size=(1500, 3))
    R = np.broadcast_to(np.eye(3), (m.P, 3, 3)).copy()
    c = m.centres0.copy()
    key = morton_codes(m.V0) if ordered else None
    nearest = NearestVertices(Y, m.labels, k=8, spare=8, groups=m.bone_of_patch, key=key)
    for _ in range(8):
        V = np.einsum("nij,nj->ni", R[m.labels], m.V0 - m.centres0[m.labels]) + c[m.labels]
        d, idx = nearest.query(V)
        d_ref, idx_ref = KDTree(V).query(Y, k=8)
        assert np.array_equal(idx, idx_ref.astype(np.int64))
        assert np.allclose(d, d_ref, rtol=1e-12, atol=1e-15)
        R = so3_exp(rng.normal(scale=10 * scale, size=(m.P, 3))) @ R
        c = c + rng.normal(scale=scale, size=(m.P, 3))
    calls = 8 * len(Y)
    assert len(Y) <= nearest.n_queried < (0.5 * calls if scale < 0.001 else calls)


def test_without_spare_candidates_every_call_queries():
    rng = np.random.default_rng(1)
    V = rng.normal(size=(300, 3))
    Y = rng.normal(size=(50, 3))
    nearest = NearestVertices(Y, np.zeros(len(V), dtype=int), k=4, spare=0)
    for _ in range(3):
        _, idx = nearest.query(V)
    assert nearest.n_queried == 150
    assert np.array_equal(idx, KDTree(V).query(Y, k=4)[1].astype(np.int64))


def test_nearest_points_of_moving_queries_equal_a_new_query():
    """Query points that move by random steps (some far, most little) get the k-d query's
    nearest fixed point every call, re-using candidates for the points that moved little."""
    rng = np.random.default_rng(4)
    Y = rng.uniform(-1, 1, size=(3000, 3))
    X = rng.uniform(-1, 1, size=(500, 3))
    nearest = NearestPoints(Y, spare=3)
    tree = KDTree(Y)
    for _ in range(6):
        d, j = nearest.query(X)
        d_ref, j_ref = tree.query(X, k=1)
        assert np.array_equal(j, j_ref.astype(np.int64))
        assert np.allclose(d, d_ref, rtol=1e-12, atol=1e-15)
        step = rng.normal(scale=0.002, size=X.shape)
        step[rng.random(len(X)) < 0.1] *= 30  # a tenth jumps 6 cm
        X = X + step
    assert len(X) < nearest.n_queried < 3 * len(X)


def test_nearest_among_is_a_stable_sort_of_the_candidates():
    """The k nearest candidates by increasing distance, ties (a vertex listed twice, two
    vertices at one place) in candidate order: a stable sort of each row's distances."""
    from meshmocap.trackers.patch.kernels import nearest_among

    rng = np.random.default_rng(3)
    V = rng.normal(size=(200, 3))
    V[10] = V[11]  # two vertices at one place
    Y = rng.normal(size=(60, 3))
    cand = rng.integers(0, 200, size=(60, 16))
    cand[:, 3] = cand[:, 7]  # a vertex listed twice
    cand[::2, 0], cand[::2, 5] = 10, 11
    for k in (1, 8, 16):
        d, idx = nearest_among(Y, V, cand, k)
        dist = np.sqrt(np.sum((V[cand] - Y[:, None]) ** 2, axis=2))
        order = np.argsort(dist, axis=1, kind="stable")[:, :k]
        assert np.array_equal(idx, np.take_along_axis(cand, order, axis=1))
        assert np.allclose(d, np.take_along_axis(dist, order, axis=1), rtol=1e-15, atol=0)


def test_morton_codes_keep_near_points_near():
    """Points sorted by their Morton codes come in runs that are compact: runs of 8 along
    the order span far less than the cloud (a curve filling space)."""
    rng = np.random.default_rng(5)
    X = rng.uniform(0, 1, size=(4096, 3))
    code = morton_codes(X)
    assert code.dtype == np.uint64 and len(np.unique(code)) > 4000
    runs = X[np.argsort(code)].reshape(-1, 8, 3)
    extent = np.ptp(runs, axis=1).max(axis=1)
    assert np.median(extent) < 0.25
