"""Validation helpers shared by the public functions."""

from __future__ import annotations

from collections.abc import Sequence

from meshmocap.errors import InputError


def check_choice(func: str, name: str, value: object, choices: Sequence[str]) -> None:
    """Raise :class:`InputError` unless ``value`` is one of ``choices`` (a Literal's values)."""
    if not isinstance(value, str) or value not in choices:
        raise InputError(f"{func}: {name} must be one of {list(choices)}, found {value!r}")
