"""The patch tracker (Huang, Boyer, Ilic, 3DV 2013; ``papers/patch-skeleton-tracking.txt``).

One method, one folder, read like its paper:

* :mod:`~meshmocap.trackers.patch.model` — the template cut into rigid patches (§III-A);
* :mod:`~meshmocap.trackers.patch.options` — the options of the tracker and its variants;
* :mod:`~meshmocap.trackers.patch.solver` — the Gauss–Newton system and Eq. (1)'s terms;
* :mod:`~meshmocap.trackers.patch.terms` — the terms beyond the paper;
* :mod:`~meshmocap.trackers.patch.kernels` — compiled inner loops (soft assignments);
* :mod:`~meshmocap.trackers.patch.tracker` — :class:`PatchTracker`, one frame at a time.
"""

from meshmocap.trackers.patch.options import PatchOptions
from meshmocap.trackers.patch.tracker import PatchTracker

__all__ = ["PatchOptions", "PatchTracker"]
