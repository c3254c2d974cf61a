"""Argument types shared by the commands: frame ranges and numbers with their valid range.

A value outside its range is refused when the arguments are parsed, in one line naming
the flag, the range and what was found (``argument --jitter: expected a number from 0 to
20 (pixels), found '1e9'``), before any work starts.
"""

from __future__ import annotations

import argparse
import math
from collections.abc import Callable


def frame_range(text: str) -> slice:
    """Parse ``START:STOP[:STEP]`` (any part optional) or a single frame ``N`` into a slice.

    START and STOP are frame numbers (≥ 0), STEP ≥ 1; ``N`` is the frame ``N:N+1``.
    Negative numbers are refused (``-3`` would otherwise silently mean "the third frame
    from the end").
    """
    parts = text.split(":")
    try:
        if len(parts) > 3:
            raise ValueError
        values = [int(p) if p.strip() else None for p in parts]
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"expected START:STOP[:STEP] with integers, found {text!r}"
        ) from None
    if len(values) == 1 and values[0] is None:
        raise argparse.ArgumentTypeError(f"expected START:STOP[:STEP] or N, found {text!r}")
    if any(v is not None and v < 0 for v in values):
        raise argparse.ArgumentTypeError(
            f"expected frame numbers ≥ 0 (START:STOP[:STEP] or N), found {text!r}"
        )
    if len(values) == 3 and values[2] is not None and values[2] < 1:
        raise argparse.ArgumentTypeError(f"expected STEP ≥ 1, found {text!r}")
    if len(values) == 1:
        return slice(values[0], values[0] + 1)
    start, stop = values[0], values[1]
    if start is not None and stop is not None and stop <= start:
        raise argparse.ArgumentTypeError(f"expected START < STOP, found {text!r} (an empty range)")
    return slice(*values)


def number(
    lo: float, hi: float, unit: str = "", *, integer: bool = False, open_lo: bool = False
) -> Callable[[str], float | int]:
    """An argparse type: a finite number in ``[lo, hi]`` (``(lo, hi]`` with ``open_lo``),
    an integer with ``integer``; ``unit`` is named in the message."""
    kind = "an integer" if integer else "a number"
    rng = f"above {lo:g} up to {hi:g}" if open_lo else f"from {lo:g} to {hi:g}"
    what = f"{kind} {rng}" + (f" ({unit})" if unit else "")

    def parse(text: str) -> float | int:
        try:
            value: float | int = int(text) if integer else float(text)
        except ValueError:
            value = math.nan
        ok = math.isfinite(value) and (value > lo if open_lo else value >= lo) and value <= hi
        if not ok:
            raise argparse.ArgumentTypeError(f"expected {what}, found {text!r}")
        return value

    parse.__name__ = "integer" if integer else "number"  # argparse names the type on errors
    return parse


def flag(name: str) -> str:
    """``--n-patches`` for the option ``n_patches``."""
    return "--" + name.replace("_", "-")
