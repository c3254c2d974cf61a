"""Validation helpers shared by the public functions."""

from __future__ import annotations

from collections.abc import Sequence

from meshmocap.errors import ArgumentTypeError, InputError


def check_choice(func: str, name: str, value: object, choices: Sequence[str]) -> None:
    """Raise :class:`InputError` unless ``value`` is one of ``choices`` (a Literal's values)."""
    if not isinstance(value, str) or value not in choices:
        raise InputError(f"{func}: {name} must be one of {list(choices)}, found {value!r}")


def check_type(
    func: str, name: str, value: object, types: type | tuple[type, ...], expected: str
) -> None:
    """Raise :class:`~meshmocap.errors.ArgumentTypeError` unless ``value`` is an instance
    of ``types`` (a bool is not taken for a number unless ``types`` names ``bool``), in one
    line: ``func: name must be EXPECTED, found TYPE VALUE``."""
    types = types if isinstance(types, tuple) else (types,)
    if isinstance(value, types) and not (isinstance(value, bool) and bool not in types):
        return
    shown = repr(value)
    shown = shown if len(shown) <= 60 else shown[:57] + "..."
    raise ArgumentTypeError(
        f"{func}: {name} must be {expected}, found {type(value).__name__} {shown}"
    )


def frame_slice(text: str, *, what: str = "frames") -> slice:
    """Parse ``START:STOP[:STEP]`` (any part optional; ``N`` alone is frame N) into a slice.

    START and STOP are frame numbers (≥ 0), STEP ≥ 1 and START < STOP when both are given:
    negative numbers are refused (``-3`` would otherwise silently mean "the third frame
    from the end"), and so are empty ranges.

    Raises :class:`InputError` naming ``what`` when ``text`` is not of that form.
    """
    parts = text.split(":")
    try:
        if len(parts) > 3:
            raise ValueError
        values = [int(p) if p.strip() else None for p in parts]
    except ValueError:
        raise InputError(
            f"{what}: expected START:STOP[:STEP] with integers, found {text!r}"
        ) from None
    if len(values) == 1 and values[0] is None:
        raise InputError(f"{what}: expected START:STOP[:STEP] or N, found {text!r}")
    if any(v is not None and v < 0 for v in values):
        raise InputError(
            f"{what}: expected frame numbers ≥ 0 (START:STOP[:STEP] or N), found {text!r}"
        )
    if len(values) == 3 and values[2] is not None and values[2] < 1:
        raise InputError(f"{what}: expected STEP ≥ 1, found {text!r}")
    if len(values) == 1:
        return slice(values[0], values[0] + 1)
    if values[0] is not None and values[1] is not None and values[1] <= values[0]:
        raise InputError(f"{what}: expected START < STOP, found {text!r} (an empty range)")
    return slice(*values)


def frame_positions(indices: Sequence[int], frames: slice) -> list[int]:
    """Positions in a capture (``indices``: its frame numbers, in order) of the frames whose
    NUMBERS the range ``frames`` (:func:`frame_slice`) selects: ``3:9`` is frames 3 to 8
    wherever the capture starts, and a frame number the capture lacks is skipped.
    Every command reads ``--frames`` this way."""
    start = 0 if frames.start is None else frames.start
    step = 1 if frames.step is None else frames.step
    return [
        k
        for k, n in enumerate(indices)
        if n >= start and (frames.stop is None or n < frames.stop) and (n - start) % step == 0
    ]
