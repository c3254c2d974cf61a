"""Self-contained HTML reports (``meshmocap report``).

* :mod:`~meshmocap.apps.report.page` — the page: tables, embedded plots and the player;
* :mod:`~meshmocap.apps.report.notes` — what the page says next to its numbers;
* :mod:`~meshmocap.apps.report.cameras` — each camera's frames with the track drawn over
  them;
* :mod:`~meshmocap.apps.report.player` — the 3D player's data, for ``assets/player.js``
  (three.js, vendored in ``assets/`` with its licence).
"""
