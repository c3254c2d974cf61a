"""A minimal progress bar on stderr (no dependency), silent when stderr is not a terminal
unless forced."""

from __future__ import annotations

import sys
import time
from collections.abc import Iterable, Iterator
from typing import TypeVar

T = TypeVar("T")


def progress(
    items: Iterable[T], *, total: int | None = None, label: str = "", enabled: bool | None = None
) -> Iterator[T]:
    """Yield ``items`` while drawing ``label [#####.....] k/n  rate it/s`` on stderr."""
    if total is None and hasattr(items, "__len__"):
        total = len(items)  # type: ignore[arg-type]
    show = sys.stderr.isatty() if enabled is None else enabled
    start = time.perf_counter()
    k = 0
    last = 0.0
    for k, item in enumerate(items, start=1):
        yield item
        now = time.perf_counter()
        if show and (now - last > 0.1 or k == total):
            last = now
            _draw(label, k, total, now - start)
    if show:
        _draw(label, k, total, time.perf_counter() - start)
        sys.stderr.write("\n")
        sys.stderr.flush()


def _draw(label: str, k: int, total: int | None, elapsed: float) -> None:
    rate = k / elapsed if elapsed > 0 else 0.0
    if total:
        filled = int(30 * k / total)
        bar = "#" * filled + "." * (30 - filled)
        text = f"\r{label:<14} [{bar}] {k}/{total}  {rate:6.1f} it/s"
    else:
        text = f"\r{label:<14} {k}  {rate:6.1f} it/s"
    sys.stderr.write(text)
    sys.stderr.flush()
