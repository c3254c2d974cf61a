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


def xy_pair(text: str) -> tuple[float, float]:
    """Parse ``X,Y`` (two finite numbers) into a tuple."""
    try:
        x, y = (float(v) for v in text.split(","))
        if not (abs(x) < float("inf") and abs(y) < float("inf")):
            raise ValueError
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected X,Y with two numbers, found {text!r}") from None
    return x, y
