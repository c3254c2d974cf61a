"""What a capture says about itself, without its answer, in three parts (one sub-package
each):

* :mod:`~meshmocap.estimate.performer` — the performer's body: estimated from the
  silhouettes, a clean mesh or the points, the tracking template chosen, and both cached
  for the capture (outside it);
* :mod:`~meshmocap.estimate.pose` — the pose: the articulated fit, many candidate poses
  scored at once, the global search of the first pose and the record of how the first
  pose was found (:class:`~meshmocap.io.results.Start`, made here, written to
  ``track.json``; messages are made from it, never parsed);
* :mod:`~meshmocap.estimate.recovery` — per-frame recovery, run on every frame: what a
  frame offers (points, normals, occupancy), the fit-quality check that flags a limb lost,
  the search for a lost limb and the re-seating of a track.

Above ``io`` (it reads captures and writes records into track folders), below
``trackers`` (the driver starts and recovers tracks through it). The performer uses the
pose's fit; the pose's first search and the recovery share the lost-limb search
(:mod:`~meshmocap.estimate.recovery.limbs`) and the candidate poses
(:mod:`~meshmocap.estimate.pose.library`). The checks of the inputs themselves (up axis,
units, plausible bodies and masks) are in :mod:`meshmocap.io`
(:mod:`~meshmocap.io.axes`, :mod:`~meshmocap.io.plausibility`).
"""
