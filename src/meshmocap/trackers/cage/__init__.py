"""The cage tracker (Duveau, Boyer et al., 3DIMPVT 2012; ``papers/cage-manifold-tracking.txt``).

One method, one folder, read like its paper:

* :mod:`~meshmocap.trackers.cage.oqr`, :mod:`~meshmocap.trackers.cage.oqr_placement`,
  :mod:`~meshmocap.trackers.cage.oqr_skinning` — Oriented Quads Rigging (§3);
* :mod:`~meshmocap.trackers.cage.cage_mesh`, :mod:`~meshmocap.trackers.cage.growth` — the
  procedural cage built on the quads and grown until it encloses the template (§3.2);
* :mod:`~meshmocap.trackers.cage.training_poses` — the poses the manifold learns from;
* :mod:`~meshmocap.trackers.cage.manifold` — the GPLVM pose manifold (§4);
* :mod:`~meshmocap.trackers.cage.quad_frames`, :mod:`~meshmocap.trackers.cage.surface` —
  the quads' frames and the deformed surface;
* :mod:`~meshmocap.trackers.cage.residuals`, :mod:`~meshmocap.trackers.cage.terms`,
  :mod:`~meshmocap.trackers.cage.energy` — the energy (§5): residuals, the term objects, the
  energy assembled from a list of them;
* :mod:`~meshmocap.trackers.cage.options` and :mod:`~meshmocap.trackers.cage.tracker` —
  :class:`CageTracker`, one frame at a time (§5–6);
* :mod:`~meshmocap.trackers.cage.transfer` — motion transfer to another body (§7).

References
----------
- E. Duveau, S. Courtemanche, L. Reveret, E. Boyer, *Cage-based motion recovery
  using manifold learning*, International Conference on 3D Imaging, Modeling,
  Processing, Visualization and Transmission (3DIMPVT), 2012.
- Y. Lipman, D. Levin, D. Cohen-Or, *Green coordinates*, ACM Transactions on Graphics
  27(3) (SIGGRAPH 2008). https://doi.org/10.1145/1360612.1360677
"""

from meshmocap.trackers.cage.options import CageOptions
from meshmocap.trackers.cage.tracker import CageTracker

__all__ = ["CageOptions", "CageTracker"]
