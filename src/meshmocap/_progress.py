"""Progress on stderr (no dependency): a bar in a terminal, a plain line every few seconds
when stderr is a file or a pipe (a long run sent to a log says it is alive and how far it
has got), nothing when disabled."""

from __future__ import annotations

import os
import sys
import time
from collections.abc import Iterable, Iterator
from typing import TypeVar

T = TypeVar("T")

#: Seconds between two log lines when stderr is not a terminal
#: (``MESHMOCAP_PROGRESS_SECONDS`` changes it).
LOG_SECONDS = 5.0


def _log_seconds() -> float:
    try:
        return max(0.0, float(os.environ.get("MESHMOCAP_PROGRESS_SECONDS", LOG_SECONDS)))
    except ValueError:
        return LOG_SECONDS


def progress(
    items: Iterable[T], *, total: int | None = None, label: str = "", enabled: bool | None = None
) -> Iterator[T]:
    """Yield ``items`` while reporting progress on stderr.

    ``enabled`` None: a bar ``label [#####.....] k/n  rate it/s`` when stderr is a
    terminal, else one line ``label: k/n (p %), rate it/s, about m min left`` every
    :data:`LOG_SECONDS` seconds (the first after that long: short runs stay quiet).
    True: the bar; False: nothing.
    """
    if total is None and hasattr(items, "__len__"):
        total = len(items)  # type: ignore[arg-type]
    tty = sys.stderr.isatty()
    show = tty if enabled is None else enabled
    log = enabled is None and not tty
    every = _log_seconds()
    start = time.perf_counter()
    k = 0
    last = 0.0
    logged = start
    for k, item in enumerate(items, start=1):
        yield item
        now = time.perf_counter()
        if show and (now - last > 0.1 or k == total):
            last = now
            _draw(label, k, total, now - start)
        elif log and now - logged >= every:
            logged = now
            _log(label, k, total, now - start)
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


def _log(label: str, k: int, total: int | None, elapsed: float) -> None:
    rate = k / elapsed if elapsed > 0 else 0.0
    text = f"{label}: {k}"
    if total:
        left = (total - k) / rate if rate > 0 else 0.0
        text += f"/{total} ({100 * k / total:.0f} %), {rate:.2f} it/s, about {_span(left)} left"
    else:
        text += f", {rate:.2f} it/s"
    sys.stderr.write(text + "\n")
    sys.stderr.flush()


def _span(seconds: float) -> str:
    if seconds < 90:
        return f"{seconds:.0f} s"
    if seconds < 5400:
        return f"{seconds / 60:.0f} min"
    return f"{seconds / 3600:.1f} h"
