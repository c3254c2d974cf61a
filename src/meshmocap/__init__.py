"""meshmocap: markerless human performance capture from 3D mesh sequences.

Units are metres, seconds and radians; the world frame is right-handed with Z up.
Importing the package changes no process-wide setting (the BLAS thread limit is applied by
the commands and the tracking driver, :mod:`meshmocap._threads`).
"""

from __future__ import annotations

__version__ = "0.1.0"
