"""
Error curves: three trackers on one capture
===========================================

A short jog, tracked by the patch tracker, the cage tracker and the articulated ICP
baseline, each scored against the capture's ground truth with
:func:`meshmocap.evaluate <meshmocap.api.evaluate>`. The curves are the mean error over the 15
evaluation joints of every frame, the papers' measure; the bars the mean error of each
joint. Every tracker starts from the first frame's true pose (``init="truth"``, the papers'
protocol, to compare the trackers alone), so errors grow from 0.
"""

import tempfile
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np

import meshmocap
from meshmocap.studio.synth import SynthSpec, synthesize

work = Path(tempfile.mkdtemp())
capture = synthesize(work / "jog", SynthSpec(motion="jog", template="neutral_5k", stop=8))

results = {}
for method in ("patch", "cage", "articulated_icp"):
    track = meshmocap.track(
        capture, method=method, out=work / method, init="truth", show_progress=False
    )
    results[method] = meshmocap.evaluate(capture, track, silhouettes=False, surface_frames=0)

# %%
# Per frame and per joint (millimetres).
fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(10, 4), gridspec_kw={"width_ratios": [1, 1.6]})
for method, ev in results.items():
    ax1.plot(ev.joints.frames, ev.joints.per_frame, marker="o", label=method)
ax1.set_xlabel("frame")
ax1.set_ylabel("mean joint error (mm)")
ax1.legend()
names = ev.joints.names
x = np.arange(len(names))
for i, (method, ev) in enumerate(results.items()):
    ax2.bar(x + (i - 1) * 0.27, ev.joints.errors.mean(axis=0), width=0.27, label=method)
ax2.set_xticks(x, names, rotation=70, fontsize=7)
ax2.set_ylabel("mean error (mm)")
fig.tight_layout()
plt.show()

# %%
# The numbers behind the curves:
for method, ev in results.items():
    s = ev.joints.overall
    print(f"{method:16s} mean {s.mean:5.1f} mm  median {s.median:5.1f}  max {s.max:5.1f}")
