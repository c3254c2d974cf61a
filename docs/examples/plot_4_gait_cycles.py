"""
Gait cycles
===========

The gait analysis of :mod:`meshmocap.analysis.gait` on a procedural walk posed on the
``neutral_5k`` template (no studio needed: the joints come straight from the rig). It finds
each foot's strikes and foot-offs from its ankle, cuts the walk into cycles and measures
hip and knee flexion over each; the same analysis runs on tracked joints
(``meshmocap gait TRACK``).
"""

import matplotlib.pyplot as plt
import numpy as np

from meshmocap.analysis.gait import gait_analysis
from meshmocap.body.procedural import walk
from meshmocap.body.template import load_template

template = load_template("neutral_5k")
fps = 60.0
motion = walk(template, duration=4.0, fps=fps, cadence=110.0)
joints = template.pose(motion.rotations, motion.root_positions).eval_joints  # (T, 15, 3)
names = template.eval_skeleton.names
gait = gait_analysis(joints, fps, names)
s = gait.summary()
print(
    f"{len(gait.cycles)} cycles, cadence {s.cadence_steps_per_min:.1f} steps/min, "
    f"stride {s.stride_length_m:.2f} m, stance {s.stance_pct:.0f} %"
)

# %%
# Ankle heights with the events, and the flexion of every cycle against its percentage.
fig, (ax1, ax2, ax3) = plt.subplots(1, 3, figsize=(12, 3.6))
for i, (side, colour) in enumerate((("left", "tab:red"), ("right", "tab:blue"))):
    ax1.plot(gait.times, gait.ankle_height[:, i], c=colour, label=f"{side} ankle")
    # events are fractional frame positions: seconds = position / fps
    for pos in gait.strikes[i]:
        ax1.axvline(pos / fps, c=colour, lw=0.8)
    for pos in gait.foot_offs[i]:
        ax1.axvline(pos / fps, c=colour, ls=":", lw=0.8)
ax1.set_xlabel("time (s); solid: foot strike, dotted: foot off")
ax1.set_ylabel("ankle height (m)")
ax1.legend(fontsize=8)
pct = np.linspace(0, 100, 101)
for c in gait.cycles:
    colour = "tab:red" if c.side == "left" else "tab:blue"
    ax2.plot(pct, c.hip, c=colour)
    ax3.plot(pct, c.knee, c=colour)
ax2.set_title("hip flexion (°)")
ax3.set_title("knee flexion (°)")
for ax in (ax2, ax3):
    ax.set_xlabel("% of the cycle")
fig.tight_layout()
plt.show()
