"""Timing helper shared by the benchmark scripts (run as ``python benchmarks/NAME.py``)."""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import TypeVar

T = TypeVar("T")


def best_of(fn: Callable[[], T], repeat: int = 5) -> tuple[float, T]:
    """Return the best wall time in seconds over ``repeat`` calls, and the last result."""
    times: list[float] = []
    out = None
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t0)
    return min(times), out  # type: ignore[return-value]


def per_call(fn: Callable[[], object], repeat: int = 7, number: int = 20) -> list[float]:
    """Per-call seconds of ``repeat`` runs of ``number`` calls each (take min or median)."""
    out = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        for _ in range(number):
            fn()
        out.append((time.perf_counter() - t0) / number)
    return out
