"""Argument types shared by the commands: frame ranges and numbers with their valid range.

A value outside its range is refused when the arguments are parsed, in one line naming
the flag, the range and what was found (``argument --jitter: expected a number from 0 to
20 (pixels), found '1e9'``), before any work starts.
"""

from __future__ import annotations

import argparse

from meshmocap._validate import frame_slice
from meshmocap.errors import InputError


def frame_range(text: str) -> slice:
    """Parse ``START:STOP[:STEP]`` (any part optional) or a single frame ``N`` into a slice
    (:func:`meshmocap._validate.frame_slice`: frame numbers ≥ 0, STEP ≥ 1, START < STOP)."""
    try:
        return frame_slice(text)
    except InputError as exc:
        raise argparse.ArgumentTypeError(str(exc).removeprefix("frames: ")) from None
