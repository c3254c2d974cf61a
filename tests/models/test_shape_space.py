"""The body-shape space: the PCA model, the bundled basis, and the exact derivatives of a
posed body and of the silhouette residuals with respect to its shape."""

from __future__ import annotations

import numpy as np
import pytest

from meshmocap.body.articulated import apply_increment, articulated_model, pose_points
from meshmocap.body.shape_space import load_shape_space
from meshmocap.body.template import load_template, template_problems
from meshmocap.errors import InputError, MeshError
from meshmocap.estimate.performer.shape_fit import frame_terms, shape_jacobian, silhouette_view
from meshmocap.geometry.rotations import so3_exp
from meshmocap.geometry.silhouette import silhouette
from meshmocap.models.shape_space import ShapeSpace
from meshmocap.studio.rigs import camera_rig


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


def test_shape_jacobian_matches_finite_differences(space):
    rng = np.random.default_rng(1)
    z = 0.5 * rng.normal(size=16)
    R = so3_exp(0.3 * rng.normal(size=(31, 3)))
    root = np.array([0.1, 0.2, 0.9])
    S = shape_jacobian(space, space.template(z), R, root)
    eps = 1e-6
    for k in (0, 5, 15):
        dz = np.zeros(16)
        dz[k] = eps
        fd = space.template(z + dz).pose(R, root).V - space.template(z - dz).pose(R, root).V
        fd /= 2 * eps
        assert np.abs(fd - S[:, :, k]).max() < 1e-6 * max(1.0, np.abs(fd).max())


def test_silhouette_residual_derivatives_match_finite_differences(space):
    """Coverage and outline residuals (fixed correspondences) against central differences
    in a random direction of shape and pose. Both Jacobians hold the metres-per-pixel factor
    constant (coverage: median error 1 %); the outline's also takes the signed distance's
    slope from its interpolated gradient, not from the bilinear interpolant itself (median
    error 2-3 %)."""
    z = np.zeros(16)
    t = space.template(z)
    R = np.tile(np.eye(3), (31, 1, 1))
    root = t.skeleton.rest_positions[0] + np.array([0.0, 0.0, 0.0])
    cams = camera_rig("ring8")[:2]
    true = space.template(np.r_[-0.3, np.zeros(15)])  # a smaller body makes the silhouettes
    views = [silhouette_view(silhouette(true.V, true.F, c, assume_closed=True), c) for c in cams]

    def terms(z, R, root):
        t = space.template(z)
        v, n, a = pose_points(articulated_model(t, n_points=t.n_vertices), R, root)
        S = shape_jacobian(space, t, R, root)
        sample = articulated_model(t, n_points=500, seed=0).sample
        return {
            term: (r, Jp, Jz)
            for term, r, Jp, Jz in frame_terms(views, v, n, a, S, t.F, sample, 25.0).rows
        }

    base = terms(z, R, root)
    rng = np.random.default_rng(2)
    dp, dz, eps = 0.3 * rng.normal(size=96), rng.normal(size=16), 1e-6
    Rp, rp = apply_increment(t.skeleton, R, root, eps * dp)
    Rm, rm = apply_increment(t.skeleton, R, root, -eps * dp)
    plus, minus = terms(z + eps * dz, Rp, rp), terms(z - eps * dz, Rm, rm)
    for term, tol in (("outline", 0.05), ("coverage", 0.015)):
        r0, Jp, Jz = base[term]
        assert len(plus[term][0]) == len(r0) == len(minus[term][0]) > 50
        fd = (plus[term][0] - minus[term][0]) / (2 * eps)
        an = Jp @ dp + Jz @ dz
        assert np.median(np.abs(fd - an)) < tol * np.median(np.abs(an)), term
