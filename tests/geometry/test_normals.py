"""Normals and solid occupancy of point clouds (meshmocap.geometry.normals)."""

import numpy as np
import pytest
from scipy import ndimage

from meshmocap.geometry.normals import solid_occupancy

RNG = np.random.default_rng(11)


def _scipy_occupancy(P: np.ndarray, h: float) -> tuple[np.ndarray, np.ndarray]:
    """solid_occupancy as scipy.ndimage's binary closing and hole filling make it."""
    origin = P.min(axis=0) - 2 * h
    ijk = np.floor((P - origin) / h + 0.5).astype(np.int64)
    occ = np.zeros(tuple(ijk.max(axis=0) + 3), dtype=bool)
    occ[tuple(ijk.T)] = True
    occ = ndimage.binary_closing(occ, iterations=1, border_value=0) | occ
    return ndimage.binary_fill_holes(occ), origin


@pytest.mark.parametrize("h", [0.02, 0.05, 0.09])
def test_solid_occupancy_is_scipy_closing_and_hole_filling(h):
    """Two nested spheres' shells (a cavity between them), a thin open cup and loose
    points: the shifted-array closing and the labelling fill give scipy's voxels exactly."""
    d = RNG.normal(size=(6000, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    cup = d[d[:, 2] < 0.3] * 0.4 + [1.2, 0.0, 0.0]
    P = np.concatenate([d * 0.5, d[:3000] * 0.25, cup, RNG.uniform(-1, 2, size=(40, 3))])
    occ, origin = solid_occupancy(P, h)
    ref, ref_origin = _scipy_occupancy(P, h)
    assert np.array_equal(origin, ref_origin) and occ.shape == ref.shape
    assert np.array_equal(occ, ref)
    centre = np.floor((np.zeros(3) - origin) / h + 0.5).astype(np.int64)
    assert occ[tuple(centre)] or h < 0.05  # the closed shell (points ≤ h apart) is filled
