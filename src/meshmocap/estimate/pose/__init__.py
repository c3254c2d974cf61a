"""The performer's pose, found from a frame alone.

* :mod:`~meshmocap.estimate.pose.fit` — the articulated Gauss–Newton fit of a template to
  observed points, and the score candidate poses are ranked by;
* :mod:`~meshmocap.estimate.pose.pose_search` — many candidate poses scored against one
  frame at once;
* :mod:`~meshmocap.estimate.pose.library` — the candidate poses: the bundled pose library
  on a template, the seed poses, the body frame;
* :mod:`~meshmocap.estimate.pose.first_pose` — the global search of the first pose;
* :mod:`~meshmocap.estimate.pose.keyframe` — the same search at a frame inside a lost run,
  helped by the tracked pose (its heading, its limbs not lost): cheap enough to run often;
* :mod:`~meshmocap.estimate.pose.start` — how a track's first pose was found, as a record
  (:class:`~meshmocap.io.results.Start`): made from the search's result, its frame flags
  and its message made from it.
"""
