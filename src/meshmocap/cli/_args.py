"""Argument types shared by the commands."""

from __future__ import annotations

import argparse

from meshmocap._validate import frame_slice
from meshmocap.errors import InputError


def frame_range(text: str) -> slice:
    """Parse ``START:STOP[:STEP]`` (any part optional) into a slice."""
    try:
        return frame_slice(text)
    except InputError as exc:
        raise argparse.ArgumentTypeError(str(exc).removeprefix("frames: ")) from None
