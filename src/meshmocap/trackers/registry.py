"""Trackers by name, for the command line and the benchmark."""

from __future__ import annotations

import importlib
from typing import Any

from meshmocap.errors import InputError
from meshmocap.trackers.base import Tracker

#: method name → (module, tracker class, options class, fixed options)
METHODS: dict[str, tuple[str, str, str, dict[str, Any]]] = {
    "patch": ("meshmocap.trackers.patch", "PatchTracker", "PatchOptions", {}),
    "patch_noclf": (
        "meshmocap.trackers.patch",
        "PatchTracker",
        "PatchOptions",
        {"classifier": "none"},
    ),
    "articulated_icp": ("meshmocap.trackers.articulated_icp", "ArticulatedICP", "ICPOptions", {}),
}


def make_tracker(method: str, **options: Any) -> Tracker:
    """Return the tracker ``method`` (see :data:`METHODS`) with ``options`` (fields of its
    options dataclass; unknown names are rejected)."""
    if method not in METHODS:
        raise InputError(f"track: method must be one of {sorted(METHODS)}, found {method!r}")
    module, cls, opts_cls, fixed = METHODS[method]
    mod = importlib.import_module(module)
    try:
        opts = getattr(mod, opts_cls)(**{**options, **fixed})
    except TypeError as exc:
        raise InputError(f"track: {exc}") from None
    return getattr(mod, cls)(opts)
