"""What a command writes to disk for a user.

* :mod:`~meshmocap.apps.files.export` — a track out of the tool (``meshmocap export``):
  BVH, C3D, TRC, glTF/GLB and CSV;
* :mod:`~meshmocap.apps.files.evaluation` — an evaluation folder (``meshmocap eval``);
* :mod:`~meshmocap.apps.files.gait` — a gait-analysis folder (``meshmocap gait``).
"""
