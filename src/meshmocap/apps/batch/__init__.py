"""Many captures at once (``meshmocap batch``).

* :mod:`~meshmocap.apps.batch.run` — the batch itself: hulls, tracking and evaluation as
  tasks on Dask, or one after another without it;
* :mod:`~meshmocap.apps.batch.items` — the captures of a batch: folders, globs, lists and
  CSV manifests;
* :mod:`~meshmocap.apps.batch.summary` — one row per capture, as CSV, markdown and a
  ``result.json`` per capture;
* :mod:`~meshmocap.apps.batch.report` — the HTML report of a batch folder.
"""
