"""Gait analysis (Fig. 11 of the cage paper) on procedural walks of known cadence."""

import numpy as np
import pytest

from meshmocap.analysis.gait import gait_analysis, write_gait_csv
from meshmocap.apps.plots import plot_gait
from meshmocap.body.procedural import walk
from meshmocap.body.template import load_template
from meshmocap.errors import InputError


@pytest.fixture(scope="module")
def walking():
    t = load_template("neutral_5k")
    m = walk(t, duration=6.0, fps=60.0, cadence=110.0)
    J = t.pose(m.rotations, m.root_positions).eval_joints
    return J, t.eval_skeleton.names


def test_cadence_and_cycles_of_a_known_walk(walking):
    J, names = walking
    g = gait_analysis(J, 60.0, names)
    assert len(g.cycles) >= 4  # 6 s at 55 cycles/min
    assert g.cadence == pytest.approx(110.0, rel=0.03)  # steps/min; ±1 frame per cycle
    # the feet alternate: right contacts fall between left ones
    left, right = g.contacts
    assert np.all(np.searchsorted(right, left[:-1]) < np.searchsorted(right, left[1:]))
    # ankles lift in swing (several cm) and wrists swing fore and aft of the pelvis
    assert g.ankle_height.max() > 0.05
    swing = np.ptp(g.wrist_sagittal[:, :, 0], axis=0)
    assert np.all(swing > 0.1)


def test_outputs(walking, tmp_path):
    J, names = walking
    g = gait_analysis(J, 60.0, names)
    assert plot_gait(g, tmp_path / "gait.png").stat().st_size > 10_000
    lines = write_gait_csv(tmp_path / "gait.csv", g).read_text().splitlines()
    assert len(lines) == len(J) + 1 and lines[0].startswith("time_s,")


def test_bad_input(walking):
    J, names = walking
    with pytest.raises(InputError, match="missing"):
        gait_analysis(J[:, :3], 60.0, names[:3])
    bad = J.copy()
    bad[4, 0, 0] = np.nan
    with pytest.raises(InputError, match="NaN"):
        gait_analysis(bad, 60.0, names)
