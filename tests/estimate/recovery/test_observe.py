"""What a frame offers every tracker and check: outward normals and a signed distance, from
any points."""

import numpy as np
import pytest

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
