"""meshmocap: markerless human performance capture from 3D mesh sequences.

Units are metres, seconds and radians; the world frame is right-handed with Z up.
"""

from __future__ import annotations

from meshmocap._threads import limit_blas_threads

__version__ = "0.1.0"

limit_blas_threads()
