"""
A tracked frame
===============

A synthetic studio capture of a walk (4 cameras, visual hulls carved from their
silhouettes, the ground truth kept), tracked by the patch tracker with the 5,000-vertex
``neutral_5k`` template from a first pose found from the capture alone (``init="auto"``,
the default; the truth only scores). We draw the last frame from the front and from the side: the
hull's points (grey), the tracked template (blue), its joints and bones (black) and the
true joints (red).
"""

import tempfile
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np

import meshmocap
from meshmocap.studio.synth import SynthSpec, synthesize

work = Path(tempfile.mkdtemp())
capture = synthesize(work / "walk", SynthSpec(motion="walk", template="neutral_5k", stop=4))
track = meshmocap.track(capture, method="patch", out=work / "walk-patch", show_progress=False)

# %%
# The last frame: the hull (a superset of the body, with phantom volume between the legs),
# the tracked vertices and joints, and the truth. Coordinates are metres, Z up; the
# subject faces −Y.
k = len(track.frames) - 1
hull_V, _ = capture[k].hull_mesh
true_J = capture[k].truth.joints
V, J = track.vertices[k], track.joints[k]
parents = track.parents

rng = np.random.default_rng(0)
hull_sample = hull_V[rng.choice(len(hull_V), 3000, replace=False)]
fig, axes = plt.subplots(1, 2, figsize=(8, 5), sharey=True)
for ax, (a, name) in zip(axes, [(0, "x (m), front view"), (1, "y (m), side view")], strict=True):
    ax.scatter(hull_sample[:, a], hull_sample[:, 2], s=1, c="0.75", label="visual hull")
    ax.scatter(V[::4, a], V[::4, 2], s=1, c="tab:blue", label="tracked template")
    for j, p in enumerate(parents):
        if p >= 0:
            ax.plot(J[[p, j], a], J[[p, j], 2], c="k", lw=1.5)
    ax.scatter(true_J[:, a], true_J[:, 2], s=18, c="tab:red", zorder=3, label="true joints")
    ax.set_xlabel(name)
    ax.set_aspect("equal")
axes[0].set_ylabel("z (m)")
axes[0].legend(loc="lower left", markerscale=2.5, fontsize=8)
errors = np.linalg.norm(J - true_J, axis=1) * 1000
fig.suptitle(f"frame {int(track.frames[k])}: mean joint error {errors.mean():.1f} mm")
plt.show()
