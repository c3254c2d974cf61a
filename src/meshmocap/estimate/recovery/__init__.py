"""Per-frame recovery: what each frame says about the track, run on every frame.

* :mod:`~meshmocap.estimate.recovery.observe` — what a frame offers every tracker and
  check: points with outward normals, a voxel occupancy and its signed distance;
* :mod:`~meshmocap.estimate.recovery.quality` — the fit-quality check, limb by limb: the
  evidence that flags a frame ``lost``;
* :mod:`~meshmocap.estimate.recovery.evidence` — frame evidence → lost limbs: the one rule
  (thresholds shipped as data, calibrated on motion categories left out) that flags a limb
  ``lost`` for every tracker, the driver after every frame and any later pass alike;
* :mod:`~meshmocap.estimate.recovery.limbs` — the search for a lost limb: the pose
  library's hypotheses for it, or its bones re-aimed over the sphere, each fitted with
  only that limb free (the first pose's search refines its candidates with it too);
* :mod:`~meshmocap.estimate.recovery.reinit` — loss detection and re-seating during
  tracking (:class:`~meshmocap.estimate.recovery.reinit.Recovery`).

This is where a pose estimate of each frame that does not depend on the previous frame
belongs (built on :mod:`meshmocap.estimate.pose`'s search, as the re-seating is), and a
global pass over a capture on disk that revisits its frames (both next in line): they are
recovery, not the tracker's step.
"""
