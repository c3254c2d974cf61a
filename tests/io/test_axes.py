"""The up axis, the units and the whereabouts of a mesh or point-cloud capture, read from
its points or refused in one line naming the option to set."""

import numpy as np
import pytest

from meshmocap.errors import InputError
from meshmocap.io.axes import detect_axes


def test_up_axis_units_and_distance_are_read_or_refused(walker):
    V = walker[3].V
    a = detect_axes(V)
    assert (a.up, a.units) == ("z", "m") and 1.5 < a.span < 2.0  # T-pose: arm span ~ height
    assert detect_axes(V * 1000).units == "mm" and detect_axes(V * 100).units == "cm"
    yup = V @ np.array([[1.0, 0, 0], [0, 0, 1], [0, -1, 0]]).T  # (x, y, z) → (x, z, −y)
    assert detect_axes(yup).up == "y"
    with pytest.raises(InputError, match="set --units") as e:
        detect_axes(V * 10)
    assert "\n" not in str(e.value)
    with pytest.raises(InputError, match="1000 km from the origin"):
        detect_axes(V + [1e6, 0.0, 0.0])
    ball = 0.3 * np.random.default_rng(1).normal(size=(500, 3))  # a crouch seen as a ball
    with pytest.raises(InputError, match="set --up"):
        detect_axes(ball)
    assert detect_axes(V * 10, units="cm").units == "cm"  # given: not detected
