"""The fit-quality check names the limb standing outside the observations and the
observations it leaves unexplained."""

import numpy as np

from meshmocap.estimate.recovery.quality import fit_quality, limb_labels
from toys import observed_frame


def test_fit_quality_names_the_limb_outside_and_unexplained(walker):
    t, R, root, posed = walker
    labels = limb_labels(t)
    obs = observed_frame(posed.V, t.F)  # the true surface, closed
    P, field = obs.points[0], obs.field
    good = fit_quality(posed.V, labels, P, field)
    assert good.lost == () and max(good.outside.values()) < 0.02
    down = R.copy()
    down[t.skeleton.index("LeftArm")] = np.eye(3)
    q = fit_quality(t.pose(down, root).V, labels, P, field)
    assert q.lost == ("left_arm",)
    assert q.outside["left_arm"] > 0.25 and q.unexplained["left_arm"] > 0.02
    assert "left_arm (" in q.describe() and "outside the observations" in q.describe()
