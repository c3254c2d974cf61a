"""The patch tracker (Huang, Boyer, Ilic, 3DV 2013; ``papers/patch-skeleton-tracking.txt``).

One method, one folder, read like its paper:

* :mod:`~meshmocap.trackers.patch.model` — the template cut into rigid patches (§III-A);
* :mod:`~meshmocap.trackers.patch.options` — the options of the tracker, and the paper's;
* :mod:`~meshmocap.trackers.patch.energy` — the energy as a list of terms (Eq. 1 and the
  extensions): a variant is a term list plus options;
* :mod:`~meshmocap.trackers.patch.solver` — the Gauss–Newton system and the math of
  Eq. (1)'s terms;
* :mod:`~meshmocap.trackers.patch.terms` — the math of the silhouette and temporal terms;
* :mod:`~meshmocap.trackers.patch.kernels` — compiled inner loops (soft assignments);
* :mod:`~meshmocap.trackers.patch.tracker` — :class:`PatchTracker`, one frame at a time.

References
----------
- C.-H. Huang, E. Boyer, S. Ilic, *Robust human body shape and pose tracking*,
  International Conference on 3D Vision (3DV), 2013.
"""

from meshmocap.trackers.patch.options import PatchOptions
from meshmocap.trackers.patch.tracker import STAGES, PatchTracker

__all__ = ["STAGES", "PatchOptions", "PatchTracker"]
