"""meshmocap: markerless human performance capture from 3D mesh sequences.

Units are metres, seconds and radians; the world frame is right-handed with Z up.
Importing the package changes no process-wide setting (the BLAS thread limit is applied by
the commands and the tracking driver, :mod:`meshmocap._threads`).
"""

from __future__ import annotations

from meshmocap._version import __version__ as __version__

#: The Python API (:mod:`meshmocap.api`), loaded on first use so that ``import meshmocap``
#: stays light: ``meshmocap.open_capture``, ``meshmocap.track``, ``meshmocap.evaluate``...
API = (
    "open_capture",
    "track",
    "TrackOptions",
    "evaluate",
    "summary",
    "open_track",
    "TrackResult",
)


def __getattr__(name: str):
    if name in API:
        from meshmocap import api

        return getattr(api, name)
    raise AttributeError(f"module 'meshmocap' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted([*globals(), *API])
