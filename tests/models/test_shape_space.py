"""The body-shape space: the PCA model, the bundled basis, and the exact derivatives of a
posed body and of the silhouette residuals with respect to its shape."""

from __future__ import annotations

import numpy as np
import pytest

from meshmocap.body.shape_space import load_shape_space
from meshmocap.body.template import load_template, template_problems
from meshmocap.errors import InputError, MeshError
from meshmocap.models.shape_space import ShapeSpace


@pytest.fixture(scope="module")
def space():
    return load_shape_space()


def body_vector(t):
    """A template as the space's body vector (vertices, heads, tails, head centre)."""
    P = t.skeleton.rest_positions
    return np.concatenate(
        [
            t.V.ravel(),
            P.ravel(),
            (P + t.skeleton.end_offsets).ravel(),
            t.eval_skeleton.rest_positions[2],
        ]
    )


def test_pca_reproduces_low_rank_data_and_standardises():
    rng = np.random.default_rng(0)
    X = rng.normal(size=(50, 3)) @ rng.normal(size=(3, 20)) + rng.normal(size=20)
    m = ShapeSpace(n_components=3).fit(X)
    assert m is not None and m.components_.shape == (3, 20)
    np.testing.assert_allclose(m.inverse_transform(m.transform(X)), X, atol=1e-10)
    np.testing.assert_allclose(m.explained_variance_ratio_.sum(), 1.0, atol=1e-12)
    np.testing.assert_allclose(m.transform(X).std(axis=0, ddof=1), 1.0, atol=1e-10)
    with pytest.raises(InputError, match=r"n_components must be in 1\.\.20"):
        ShapeSpace(n_components=21).fit(X)


def test_bundled_space_holds_the_bundled_bodies(space):
    """heavy_male and small_female are not among the bodies the space was made from; their
    projections reproduce them to about 1 mm (the tool measured 0.92 and 0.44 mm)."""
    assert space.n_components == 16 and space.n_vertices == 12411
    assert space.model.explained_variance_ratio_.sum() > 0.9999
    for name in ("heavy_male", "small_female"):
        t = load_template(name)
        z = space.model.transform(body_vector(t)[None])[0]
        b = space.body(z)
        err = np.linalg.norm(b.V - t.V, axis=1)
        assert err.mean() < 1.5e-3 and err.max() < 1e-2
        assert np.abs(b.heads - t.skeleton.rest_positions).max() < 5e-3
        assert np.abs(b.eval_rest - t.eval_skeleton.rest_positions).max() < 5e-3
    mean = space.template(np.zeros(16), name="mean")
    assert template_problems(mean) == [] and mean.name == "mean"
    assert 1.6 < np.ptp(mean.V[:, 2]) < 1.9
    with pytest.raises(InputError, match="16 finite coefficients"):
        space.body(np.zeros(3))


def test_a_bad_shape_space_file_is_named(tmp_path):
    bad = tmp_path / "x.npz"
    np.savez(bad, format=np.str_("other"))
    with pytest.raises(MeshError, match="expected format 'meshmocap-shape-space-1'"):
        load_shape_space(bad)
