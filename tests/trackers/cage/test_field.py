"""The cage tracker's distance field against LazyDistanceGrid (trackers/cage/field.py)."""

import numpy as np
import pytest

from meshmocap.errors import InputError
from meshmocap.geometry.distance_field import LazyDistanceGrid
from meshmocap.trackers.cage.field import HullDistanceField


def _blob(rng, shape=(23, 17, 31)):
    """Two overlapping ellipsoids and a stray voxel, touching the grid's border."""
    x, y, z = np.indices(shape)
    occ = ((x - 8) / 7.0) ** 2 + ((y - 8) / 6.0) ** 2 + ((z - 12) / 11.0) ** 2 < 1
    occ |= ((x - 16) / 7.0) ** 2 + ((y - 9) / 9.0) ** 2 + ((z - 24) / 8.0) ** 2 < 1
    occ[2, 15, 2] = True
    return occ


@pytest.mark.parametrize(("pad", "stride"), [(1, 1), (3, 2), (6, 3)])
def test_values_gradients_and_boundary_equal_lazy_distance_grid(pad, stride):
    rng = np.random.default_rng(pad)
    occ, origin, h = _blob(rng), np.array([0.3, -1.2, 0.05]), 0.01
    a = LazyDistanceGrid(occ, origin, h, pad=pad, stride=stride)
    b = HullDistanceField(occ, origin, h, pad=pad, stride=stride)
    assert b.shape == a.shape
    np.testing.assert_array_equal(b.origin, a.origin)
    np.testing.assert_array_equal(b.spacing, a.spacing)
    np.testing.assert_array_equal(b.boundary, a.boundary)  # the same order too
    centre = origin + h * np.array(occ.shape) / 2
    for scale in (0.02, 0.1, 0.4):  # near the surface, across the box, far outside it
        P = centre + rng.normal(scale=scale, size=(500, 3))
        va, ga = a.value_and_gradient(P)
        vb, gb = b.value_and_gradient(P)
        inside = np.all((a.origin <= P) & (a.upper >= P), axis=1)
        # the same grid values (a nearest distance is unique): the same arithmetic, bit
        # for bit inside the box; outside it the distance to the box is summed in another
        # order (rounding)
        np.testing.assert_array_equal(vb[inside], va[inside])
        np.testing.assert_array_equal(gb[inside], ga[inside])
        np.testing.assert_allclose(vb, va, rtol=1e-14, atol=1e-15)
        np.testing.assert_allclose(gb, ga, rtol=0, atol=1e-12)
    assert b.n_evaluated == a.n_evaluated  # the same grid points, each computed once
    np.testing.assert_array_equal(b(P), vb)


@pytest.mark.parametrize("stride", [1, 2, 3])
def test_lookups_one_at_a_time_meet_every_mix_of_known_corners(stride):
    """Points looked up one by one, near the surface and far off: a cell's corners are
    partly known from its neighbours' lookups (a new corner alone, or 2 to 8 new ones found
    in one pass over the buckets); every value and gradient is LazyDistanceGrid's."""
    rng = np.random.default_rng(10 + stride)
    occ, origin, h = _blob(rng), np.array([0.3, -1.2, 0.05]), 0.01
    a = LazyDistanceGrid(occ, origin, h, pad=4, stride=stride)
    b = HullDistanceField(occ, origin, h, pad=4, stride=stride)
    centre = origin + h * np.array(occ.shape) / 2
    scale = rng.choice([0.01, 0.05, 0.2], size=400)
    P = centre + scale[:, None] * rng.normal(size=(400, 3))
    inside = np.all((a.origin <= P) & (a.upper >= P), axis=1)
    for p in P[inside]:
        va, ga = a.value_and_gradient(p[None])
        vb, gb = b.value_and_gradient(p[None])
        np.testing.assert_array_equal(vb, va)
        np.testing.assert_array_equal(gb, ga)
    assert b.n_evaluated == a.n_evaluated


def test_bad_input_is_one_line():
    occ = np.zeros((4, 4, 4), dtype=bool)
    with pytest.raises(InputError, match=r"non-empty 3-D occupancy.*found shape"):
        HullDistanceField(occ, np.zeros(3), 0.01)
    occ[1, 1, 1] = True
    with pytest.raises(InputError, match="stride 0"):
        HullDistanceField(occ, np.zeros(3), 0.01, stride=0)
    with pytest.raises(InputError, match=r"spacing -1\.0"):
        HullDistanceField(occ, np.zeros(3), -1.0)
    f = HullDistanceField(occ, np.zeros(3), 0.01)
    with pytest.raises(InputError, match="finite"):
        f.value_and_gradient(np.array([[np.nan, 0.0, 0.0]]))
