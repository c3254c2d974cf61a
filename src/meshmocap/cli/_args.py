"""Argument types shared by the commands: frame ranges and numbers with their valid range.

A value outside its range is refused when the arguments are parsed, in one line naming
the flag, the range and what was found (``argument --jitter: expected a number from 0 to
20 (pixels), found '1e9'``), before any work starts.
"""

from __future__ import annotations

import argparse
import math
from collections.abc import Callable, Iterable
from pathlib import Path

from meshmocap._validate import frame_slice
from meshmocap.errors import InputError


def frame_range(text: str) -> slice:
    """Parse ``START:STOP[:STEP]`` (any part optional) or a single frame ``N`` into a slice
    (:func:`meshmocap._validate.frame_slice`: frame numbers ≥ 0, STEP ≥ 1, START < STOP)."""
    try:
        return frame_slice(text)
    except InputError as exc:
        raise argparse.ArgumentTypeError(str(exc).removeprefix("frames: ")) from None


def add_restart(parser: argparse.ArgumentParser, what: str) -> None:
    """``--restart``: start over instead of resuming, the same flag on every command that
    resumes (``what`` says what is redone); ``--overwrite`` is kept as a hidden alias."""
    parser.add_argument("--restart", action="store_true", help=f"start over: {what}")
    parser.add_argument("--overwrite", dest="restart", action="store_true", help=argparse.SUPPRESS)


def add_frames(parser: argparse.ArgumentParser, what: str = "") -> None:
    """``--frames START:STOP[:STEP]``: frame NUMBERS (not positions) on every command that
    reads frames (:func:`meshmocap._validate.frame_positions`)."""
    parser.add_argument(
        "--frames",
        type=frame_range,
        help="frame numbers START:STOP[:STEP] (STOP excluded)" + (f"; {what}" if what else ""),
    )


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


def xy_pair(text: str) -> tuple[float, float]:
    """Parse ``X,Y`` (two finite numbers) into a tuple."""
    try:
        x, y = (float(v) for v in text.split(","))
        if not (math.isfinite(x) and math.isfinite(y)):
            raise ValueError
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected X,Y with two numbers, found {text!r}") from None
    return x, y


def check_track_folders(command: str, paths: Iterable[str]) -> None:
    """Refuse, in ``command``'s words, a path that is not a track folder (one with the
    ``track.json`` that ``meshmocap track`` writes), before any work."""
    for path in paths:
        p = Path(path)
        found = (
            "it does not exist"
            if not p.exists()
            else "it is a file"
            if not p.is_dir()
            else "it has no track.json"
        )
        if not (p / "track.json").is_file():
            raise InputError(
                f"{command}: {path} is not a track folder ({found}); expected a folder "
                "written by 'meshmocap track'"
            )
