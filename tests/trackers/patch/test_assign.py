"""The patch tracker's compiled E-step gives the numpy E-step's pairs and weights."""

import numpy as np
import pytest

from meshmocap.body.template import load_template
from meshmocap.geometry.mesh import vertex_normals
from meshmocap.trackers.patch.tracker import PatchTracker


def _reference(tracker, Y, NY, ycls, Vc, Nc):
    """The E-step as numpy array expressions (before the compiled loop)."""
    from pykdtree.kdtree import KDTree

    o, m = tracker.opts, tracker.model
    K = min(o.k_neighbours, len(Vc))
    d, idx = KDTree(Vc).query(Y, k=K)
    d, idx = d.reshape(len(Y), K), idx.reshape(len(Y), K).astype(np.int64)
    ok = np.einsum("pkj,pj->pk", np.take(Nc, idx, axis=0), NY) > o.normal_cos
    if ycls is not None:
        ok &= (m.bone_of_patch[m.labels[idx]] == ycls[:, None]) | (ycls[:, None] < 0)
    i, j = np.nonzero(ok)
    patch = m.labels[idx[i, j]]
    _, first = np.unique(i * m.P + patch, return_index=True)
    i, j, patch = i[first], j[first], patch[first]
    p = np.exp(-0.5 * d[i, j].astype(np.float64) ** 2 / tracker.sigma**2)
    denom = np.bincount(i, p, minlength=len(Y)) + np.exp(-0.5 * o.outlier_sigmas**2)
    return patch, idx[i, j], p / denom[i], Y[i], NY[i]


@pytest.mark.parametrize("classes", [False, True])
def test_assign_equals_the_numpy_e_step(classes):
    t = load_template("neutral_5k")
    tracker = PatchTracker()
    tracker.setup(t)
    rng = np.random.default_rng(2)
    Vc, Nc = t.V, vertex_normals(t.V, t.F)
    pick = rng.choice(len(Vc), 3000, replace=False)
    Y = Vc[pick] + rng.normal(scale=0.01, size=(3000, 3))
    NY = Nc[pick] + rng.normal(scale=0.3, size=(3000, 3))
    NY /= np.linalg.norm(NY, axis=1, keepdims=True)
    tracker.sigma = 0.02
    ycls = rng.integers(-1, tracker.model.bone_of_patch.max() + 1, 3000) if classes else None
    k = tracker.correspondences(Y, NY, ycls, Vc, Nc)
    got = (k.patch, k.vertex, k.weight, k.point, k.normal)
    ref = _reference(tracker, Y, NY, ycls, Vc, Nc)
    for a, b in zip(got[:2] + got[3:], ref[:2] + ref[3:], strict=True):
        assert np.array_equal(a, b)
    assert np.allclose(got[2], ref[2], rtol=1e-14, atol=0)  # exp to the last bit or one off
    assert 500 < len(got[0]) < 3000 * tracker.opts.k_neighbours  # some pairs, not all
