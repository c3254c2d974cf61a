"""Validation helpers shared by the public functions.

Options dataclasses state their constraints once, as data, in the spirit of
scikit-learn's ``utils._param_validation``: a table maps each option to a constraint
(:class:`Interval`, :class:`Options`, :class:`Boolean`, :class:`Names`, :class:`Strings`,
or ``None``: the value None is allowed), or to a tuple of them (any one suffices), and
:func:`check_options` walks the table. Its error is one line that names the options class,
the option, what it must be and the value found.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from numbers import Integral, Real
from typing import Any, Literal

from meshmocap.errors import ArgumentTypeError, InputError


@dataclass(frozen=True)
class Interval:
    """A number of type ``kind`` (:class:`numbers.Integral` or :class:`numbers.Real`; bool
    is neither) between ``low`` and ``high`` (None: unbounded on that side; then the
    number must be finite there), ``closed`` on the ``"left"``, ``"right"``, ``"both"`` or
    ``"neither"`` side. NaN never satisfies it; ±inf only as a closed bound."""

    kind: type
    low: float | None
    high: float | None
    closed: Literal["left", "right", "both", "neither"] = "left"

    def __call__(self, value: Any) -> bool:
        if isinstance(value, bool) or not isinstance(value, self.kind):
            return False
        if self.kind is Real and math.isnan(value):
            return False
        left, right = self.closed in ("left", "both"), self.closed in ("right", "both")
        if self.low is None:
            ok_low = value > -math.inf
        else:
            ok_low = value >= self.low if left else value > self.low
        if self.high is None:
            ok_high = value < math.inf
        else:
            ok_high = value <= self.high if right else value < self.high
        return bool(ok_low and ok_high)

    def __str__(self) -> str:
        what = "an integer" if self.kind is Integral else "a number"
        left, right = self.closed in ("left", "both"), self.closed in ("right", "both")
        if self.high is None and self.low is not None:
            return f"{what} {'≥' if left else '>'} {self.low:g}"
        if self.low is None and self.high is not None:
            return f"{what} {'≤' if right else '<'} {self.high:g}"
        if self.low is None:
            return f"a finite {what.split()[-1]}"
        return f"{what} in {'[' if left else '('}{self.low:g}, {self.high:g}{']' if right else ')'}"


@dataclass(frozen=True)
class Options:
    """One of ``choices`` (a Literal's values)."""

    choices: tuple

    def __call__(self, value: Any) -> bool:
        return isinstance(value, str) and value in self.choices

    def __str__(self) -> str:
        return f"one of {list(self.choices)}"


@dataclass(frozen=True)
class Boolean:
    """True or False."""

    def __call__(self, value: Any) -> bool:
        return isinstance(value, bool)

    def __str__(self) -> str:
        return "True or False"


@dataclass(frozen=True)
class Names:
    """A list or tuple of distinct names from ``choices`` that holds every name of
    ``required``."""

    choices: tuple
    required: tuple = ()

    def __call__(self, value: Any) -> bool:
        if not isinstance(value, list | tuple):
            return False
        names = list(value)
        return (
            all(isinstance(n, str) and n in self.choices for n in names)
            and len(set(names)) == len(names)
            and all(r in names for r in self.required)
        )

    def __str__(self) -> str:
        held = f" holding {list(self.required)}" if self.required else ""
        return f"distinct names from {list(self.choices)}{held}"


@dataclass(frozen=True)
class Strings:
    """A list or tuple of strings (not one string)."""

    what: str = "names"

    def __call__(self, value: Any) -> bool:
        return isinstance(value, list | tuple) and all(isinstance(v, str) for v in value)

    def __str__(self) -> str:
        return f"a sequence of {self.what}"


#: A table row: a constraint, None (the value None is allowed), or a tuple of them (any).
Constraint = Interval | Options | Boolean | Names | Strings | None


def satisfies(value: Any, constraint: Constraint | tuple) -> bool:
    """Whether ``value`` satisfies ``constraint`` (a tuple: any one of them)."""
    if isinstance(constraint, tuple):
        return any(satisfies(value, c) for c in constraint)
    return value is None if constraint is None else constraint(value)


def describe(constraint: Constraint | tuple) -> str:
    """What ``constraint`` asks, in words (``a number ≥ 0 or None``)."""
    if isinstance(constraint, tuple):
        return " or ".join(describe(c) for c in constraint)
    return "None" if constraint is None else str(constraint)


def check_options(owner: str, options: Any, table: Mapping[str, Constraint | tuple]) -> None:
    """Check every option of ``options`` (a dataclass instance) that ``table`` names.

    Raises
    ------
    InputError
        One line: ``"{owner}: {option} must be {constraint}, found {value!r}"`` for the
        first option, in table order, whose value does not satisfy its row.
    """
    for name, constraint in table.items():
        value = getattr(options, name)
        if not satisfies(value, constraint):
            raise InputError(f"{owner}: {name} must be {describe(constraint)}, found {value!r}")


def counted(n: int, noun: str, plural: str | None = None) -> str:
    """``n`` and ``noun`` in words: ``"1 frame"``, ``"2 frames"`` (``plural``: the noun's
    plural where it is not ``noun + "s"``)."""
    return f"{n} {noun if n == 1 else plural or noun + 's'}"


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
