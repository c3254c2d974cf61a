"""Validation helpers shared by the public functions."""

from __future__ import annotations

from collections.abc import Sequence

from meshmocap.errors import InputError


def check_choice(func: str, name: str, value: object, choices: Sequence[str]) -> None:
    """Raise :class:`InputError` unless ``value`` is one of ``choices`` (a Literal's values)."""
    if not isinstance(value, str) or value not in choices:
        raise InputError(f"{func}: {name} must be one of {list(choices)}, found {value!r}")


def frame_slice(text: str, *, what: str = "frames") -> slice:
    """Parse ``START:STOP[:STEP]`` (any part optional; ``N`` alone is frame N) into a slice.

    Raises :class:`InputError` naming ``what`` when ``text`` is not of that form.
    """
    parts = text.split(":")
    try:
        if len(parts) > 3:
            raise ValueError
        if len(parts) == 1:
            return slice(int(text), int(text) + 1)
        return slice(*(int(p) if p.strip() else None for p in parts))
    except ValueError:
        raise InputError(
            f"{what}: expected START:STOP[:STEP] with integers, found {text!r}"
        ) from None
