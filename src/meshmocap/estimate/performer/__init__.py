"""The performer's body, estimated from the capture itself, and the template a capture is
tracked with.

* :mod:`~meshmocap.estimate.performer.subject` — the body from a studio capture's
  silhouettes (the shape space, :mod:`~meshmocap.estimate.performer.shape_fit`) or from a
  clean mesh (rigged as it stands);
* :mod:`~meshmocap.estimate.performer.point_subject` — the body from hulls or point clouds
  without cameras;
* :mod:`~meshmocap.estimate.performer.tracking_template` — which template a capture is
  tracked with (given, named by the capture, or estimated), and the start a template made
  from a frame knows;
* :mod:`~meshmocap.estimate.performer.first_frame` — the first frame's pose on the default
  path: the search's or the body fit's, each fitted to the silhouettes, by evidence;
* :mod:`~meshmocap.estimate.performer.capture_cache` — the body and the first pose
  estimated once per capture and cached for it (outside the capture).
"""
