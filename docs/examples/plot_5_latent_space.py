"""
The cage tracker's pose manifold
================================

The cage tracker keeps its quads on a pose manifold: a back-constrained GPLVM (the cage
paper's §4) learned from motion retargeted onto the template. Here it is learned from the
procedural walk and jog on ``neutral_5k`` (what ``meshmocap learn walk jog`` does), and
drawn as the paper's Fig. 2: the training poses in the 2-D latent space over the model's
predictive variance (dark: poses the model is sure of).
"""

import matplotlib.pyplot as plt
import numpy as np

from meshmocap.body.template import load_template
from meshmocap.trackers.cage.manifold import learn_pose_manifold

template = load_template("neutral_5k")
manifold = learn_pose_manifold(template, ["walk", "jog"], n_samples=80, max_iter=500)
gp = manifold.gp
X = gp.X_
print(
    f"{len(X)} poses from {manifold.n_poses}, fitted in {manifold.fit_seconds:.1f} s; "
    f"log-likelihood {gp.log_likelihood_:.1f}"
)

# %%
# The variance over a grid of latent points, and the training poses by group.
lo, hi = X.min(0), X.max(0)
pad = 0.15 * (hi - lo)
g0, g1 = np.meshgrid(
    np.linspace(lo[0] - pad[0], hi[0] + pad[0], 80), np.linspace(lo[1] - pad[1], hi[1] + pad[1], 80)
)
_, var = gp.predict(np.column_stack([g0.ravel(), g1.ravel()]), return_var=True)
fig, ax = plt.subplots(figsize=(6, 5))
im = ax.pcolormesh(g0, g1, np.log(var.reshape(g0.shape)), cmap="gray", shading="auto")
fig.colorbar(im, label="log predictive variance")
for group, marker in (("walk", "o"), ("jog", "^")):
    m = manifold.groups == group
    ax.scatter(X[m, 0], X[m, 1], s=18, marker=marker, label=group)
ax.set_xlabel("latent 1")
ax.set_ylabel("latent 2")
ax.legend()
plt.show()
