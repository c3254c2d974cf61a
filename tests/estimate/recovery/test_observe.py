"""What a frame offers every tracker and check: outward normals and a signed distance, from
any points."""

import numpy as np
import pytest

from meshmocap.estimate.recovery.observe import observed
from toys import observed_frame


def test_a_point_cloud_frame_has_outward_normals_and_a_signed_distance():
    k = np.arange(20000) + 0.5  # a sphere sampled evenly (Fibonacci lattice), 7.5 mm apart
    z, phi = 1 - 2 * k / len(k), np.pi * (1 + 5**0.5) * k
    d = np.stack([np.sqrt(1 - z**2) * np.cos(phi), np.sqrt(1 - z**2) * np.sin(phi), z], 1)
    P = 0.3 * d + [1.0, 2.0, 0.5]
    obs = observed_frame(P)  # a cloud without normals: estimated (geometry.normals)
    Q, N = obs.points
    radial = (Q - [1.0, 2.0, 0.5]) / 0.3
    assert np.percentile(np.sum(N * radial, axis=1), 5) > 0.9  # outward, 5th percentile
    inside = obs.field(np.array([[1.0, 2.0, 0.5], [1.0, 2.0, 1.2]]))
    assert inside[0] == pytest.approx(-0.3, abs=0.02) and inside[1] == pytest.approx(0.4, abs=0.02)


def test_the_surface_alone_is_the_points_without_their_normals(small_walk):
    """``surface`` reads a hull's vertices without computing normals; ``points`` then
    reuses them."""
    obs = observed(small_walk[3])
    P = obs.surface
    assert "points" not in vars(obs)
    V, N = obs.points
    assert V is P and N.shape == P.shape
    np.testing.assert_array_equal(P, np.asarray(small_walk[3].hull_mesh[0], dtype=np.float64))
