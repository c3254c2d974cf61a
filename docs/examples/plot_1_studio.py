"""
The studio: silhouettes and a visual hull
=========================================

What a multi-view studio gives the trackers. A synthetic capture renders the template
posed by a walk into the silhouettes of four cameras placed like HumanEva-II's
(``humaneva4``), and carves the visual hull from them: every 1 cm voxel that all the
cameras that see it see as subject. The hull contains the body and more: the *phantom
volume* that four views cannot carve away (here between the legs and around the arms).
"""

import tempfile
from pathlib import Path

import matplotlib.pyplot as plt

from meshmocap.studio.synth import SynthSpec, synthesize

work = Path(tempfile.mkdtemp())
capture = synthesize(work / "walk", SynthSpec(motion="walk", template="neutral_5k", stop=1))
frame = capture[0]

# %%
# The four silhouettes, as the cameras see them (``silhouettes/<camera>/00000.png``).
fig, axes = plt.subplots(1, 4, figsize=(12, 2.6))
for ax, camera, mask in zip(axes, frame.cameras, frame.silhouettes, strict=True):
    ax.imshow(mask, cmap="gray")
    ax.set_title(f"{camera.name} ({camera.width}×{camera.height})", fontsize=9)
    ax.axis("off")
plt.show()

# %%
# The hull's surface against the true body, seen from the side: the hull (grey) is a
# superset of the body (blue).
hull_V, _ = frame.hull_mesh
true_V = frame.truth.vertices
fig, ax = plt.subplots(figsize=(4, 5))
ax.scatter(hull_V[::3, 1], hull_V[::3, 2], s=1, c="0.7", label="visual hull")
ax.scatter(true_V[:, 1], true_V[:, 2], s=1, c="tab:blue", label="true surface")
ax.set_xlabel("y (m)")
ax.set_ylabel("z (m)")
ax.set_aspect("equal")
ax.legend(markerscale=6, fontsize=8)
plt.show()
print(
    f"hull: {len(hull_V)} vertices; occupancy grid {frame.hull.occupancy.shape}, "
    f"{frame.hull.occupancy.sum() * 1e-6:.3f} m³ of voxels at 1 cm"
)
