"""Both papers side by side in one reproducible run (``meshmocap bench``).

* :mod:`~meshmocap.apps.bench.run` — the protocol: every method on every capture of a set;
* :mod:`~meshmocap.apps.bench.captures` — the named capture sets and the captures made;
* :mod:`~meshmocap.apps.bench.rows` — one result per (capture, method), and the
  kept-fraction sweep's points;
* :mod:`~meshmocap.apps.bench.report` — the CSV and markdown files;
* :mod:`~meshmocap.apps.bench.plots` — the PNG plots.
"""
