"""Argument types shared by the commands."""

from __future__ import annotations

import argparse


def frame_range(text: str) -> slice:
    """Parse ``START:STOP[:STEP]`` (any part optional) into a slice."""
    parts = text.split(":")
    try:
        if len(parts) > 3:
            raise ValueError
        return (
            slice(*(int(p) if p else None for p in parts))
            if len(parts) > 1
            else slice(int(text), int(text) + 1)
        )
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"expected START:STOP[:STEP] with integers, found {text!r}"
        ) from None
