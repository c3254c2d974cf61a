"""The output surface refined towards observations along its normals (geometry/refine.py)."""

import numpy as np
import pytest
import trimesh

from meshmocap.errors import InputError
from meshmocap.geometry.mesh import vertex_normals
from meshmocap.geometry.refine import SurfaceRefiner


@pytest.fixture(scope="module")
def sphere():
    s = trimesh.creation.icosphere(subdivisions=3, radius=0.2)  # 642 vertices, ~2 cm apart
    return np.asarray(s.vertices, np.float64), np.asarray(s.faces, np.int64)


def _observed(radius: float, n: int = 4000, seed: int = 0):
    """Points of a sphere of ``radius`` (m) at random, with outward normals."""
    x = np.random.default_rng(seed).normal(size=(n, 3))
    N = x / np.linalg.norm(x, axis=1, keepdims=True)
    return radius * N, N


def test_a_surface_inside_its_observation_moves_out_onto_it(sphere):
    V, F = sphere
    P, N = _observed(0.215)  # 15 mm further out
    out = SurfaceRefiner(F, len(V)).refine(V, P, N)
    r = np.linalg.norm(out, axis=1)
    # the pull back to the tracked surface (stiffness 0.05 against ~2 matches) keeps it a
    # few per cent of the way short; the sampled points' scatter adds under a millimetre
    assert np.abs(r - 0.215).mean() < 1.5e-3 and np.abs(r - 0.215).max() < 4e-3
    # along the normals only: each vertex moves along its own normal
    n = vertex_normals(V, F)
    d = out - V
    np.testing.assert_allclose(d, np.einsum("ij,ij->i", d, n)[:, None] * n, atol=1e-12)


def test_what_is_not_observed_stays_where_the_skeleton_put_it(sphere):
    V, F = sphere
    P, N = _observed(0.215)
    top = P[:, 2] > 0.05  # only the top is seen
    out = SurfaceRefiner(F, len(V)).refine(V, P[top], N[top])
    r = np.linalg.norm(out, axis=1)
    assert np.abs(r[V[:, 2] > 0.1] - 0.215).max() < 4e-3
    # the displacement fades away from what is seen (smooth, pulled back to the skin)
    top, side, bottom = (
        r[m].mean() - 0.2 for m in (V[:, 2] > 0.1, np.abs(V[:, 2]) < 0.03, V[:, 2] < -0.15)
    )
    assert top > side > bottom and bottom < 0.6 * top


def test_nothing_observed_or_nothing_compatible_leaves_the_surface(sphere):
    V, F = sphere
    ref = SurfaceRefiner(F, len(V))
    np.testing.assert_array_equal(ref.refine(V, np.zeros((0, 3)), np.zeros((0, 3))), V)
    P, N = _observed(0.21)
    # normals pointing inwards: another surface (the inside of a sleeve), not this one
    np.testing.assert_array_equal(ref.refine(V, P, -N), V)
    far, _ = _observed(0.4)  # 20 cm away: out of reach
    np.testing.assert_array_equal(ref.refine(V, far, N), V)


def test_a_refined_surface_keeps_its_detail(sphere):
    """A bump on the tracked surface rides along: the displacement is smooth, the shape
    under it is the template's."""
    V, F = sphere
    bumped = V.copy()
    bumped[0] *= 1.05  # 1 cm bump at one vertex
    P, N = _observed(0.21)
    out = SurfaceRefiner(F, len(V)).refine(bumped, P, N)
    n = vertex_normals(bumped, F)
    # the bump's vertex moved out by about as much as its neighbours (a smooth field)
    u = np.einsum("ij,ij->i", out - bumped, n)
    assert abs(u[0] - np.median(u)) < 6e-3 and np.linalg.norm(out[0]) > 0.214


def test_bad_arguments_are_refused_in_one_line(sphere):
    V, F = sphere
    with pytest.raises(InputError, match="F must be"):
        SurfaceRefiner(F, 10)
    with pytest.raises(InputError, match="reach must be > 0"):
        SurfaceRefiner(F, len(V), reach=0.0)
    with pytest.raises(InputError, match="iterations"):
        SurfaceRefiner(F, len(V), iterations=0)
