"""Progress on stderr (no dependency): a bar in a terminal, a plain line every few seconds
when stderr is a file or a pipe (a long run sent to a log says it is alive and how far it
has got), nothing when disabled; and :func:`phase`, a line for every step of more than
:data:`PHASE_SECONDS` that has no bar (estimating the body, finding the first pose,
exporting, writing the report).

The time left is the items left over a **moving rate**: the last :data:`RATE_WINDOW` items,
never the first one, whose time is mostly compiling and setting up (a 40-frame track whose
first frame took 25 s of a 40 s run would otherwise say "about 30 min left").
"""

from __future__ import annotations

import os
import sys
import threading
import time
from collections import deque
from collections.abc import Iterable, Iterator
from contextlib import contextmanager
from typing import TypeVar

from meshmocap._tolerances import ZERO_EXTENT

T = TypeVar("T")

#: Seconds between two log lines when stderr is not a terminal
#: (``MESHMOCAP_PROGRESS_SECONDS`` changes it).
LOG_SECONDS = 5.0
#: Items the moving rate is measured over.
RATE_WINDOW = 10
#: A :func:`phase` that runs longer than this (seconds) says what it is doing.
PHASE_SECONDS = 2.0


def _log_seconds() -> float:
    try:
        return max(0.0, float(os.environ.get("MESHMOCAP_PROGRESS_SECONDS", LOG_SECONDS)))
    except ValueError:
        return LOG_SECONDS


class _Rate:
    """Items per second over the last :data:`RATE_WINDOW` items, the first one left out."""

    def __init__(self) -> None:
        self.stamps: deque[float] = deque(maxlen=RATE_WINDOW + 1)

    def add(self, now: float) -> None:
        self.stamps.append(now)  # the first item's end starts the clock

    def rate(self) -> float | None:
        if len(self.stamps) < 2:
            return None
        return (len(self.stamps) - 1) / max(self.stamps[-1] - self.stamps[0], ZERO_EXTENT)


def progress(
    items: Iterable[T], *, total: int | None = None, label: str = "", enabled: bool | None = None
) -> Iterator[T]:
    """Yield ``items`` while reporting progress on stderr.

    ``enabled`` None: a bar ``label [#####.....] k/n  rate it/s`` when stderr is a
    terminal, else one line ``label: k/n (p %), rate it/s, about m min left`` every
    :data:`LOG_SECONDS` seconds (the first after that long: short runs stay quiet).
    True: the bar; False: nothing. The rate is the moving rate of the module docstring.
    """
    if total is None and hasattr(items, "__len__"):
        total = len(items)  # type: ignore[arg-type]
    tty = sys.stderr.isatty()
    show = tty if enabled is None else enabled
    log = enabled is None and not tty
    every = _log_seconds()
    start = time.perf_counter()
    rate = _Rate()
    k = 0
    last = 0.0
    logged = start
    for k, item in enumerate(items, start=1):
        yield item
        now = time.perf_counter()
        rate.add(now)
        if show and (now - last > 0.1 or k == total):
            last = now
            _draw(label, k, total, rate.rate())
        elif log and now - logged >= every:
            logged = now
            _log(label, k, total, rate.rate())
    if show:
        _draw(label, k, total, rate.rate())
        sys.stderr.write("\n")
        sys.stderr.flush()


def _draw(label: str, k: int, total: int | None, rate: float | None) -> None:
    speed = f"{rate:6.1f} it/s" if rate else "     … it/s"
    if total:
        filled = int(30 * k / total)
        bar = "#" * filled + "." * (30 - filled)
        left = f", {_span((total - k) / rate)} left" if rate and k < total else ""
        text = f"\r{label:<14} [{bar}] {k}/{total}  {speed}{left}   "
    else:
        text = f"\r{label:<14} {k}  {speed}"
    sys.stderr.write(text)
    sys.stderr.flush()


def _log(label: str, k: int, total: int | None, rate: float | None) -> None:
    text = f"{label}: {k}"
    if total:
        text += f"/{total} ({100 * k / total:.0f} %)"
        if rate:
            text += f", {rate:.2f} it/s, about {_span((total - k) / rate)} left"
        else:
            text += ", estimating the time left"
    elif rate:
        text += f", {rate:.2f} it/s"
    sys.stderr.write(text + "\n")
    sys.stderr.flush()


def _span(seconds: float) -> str:
    if seconds < 90:
        return f"{seconds:.0f} s"
    if seconds < 5400:
        return f"{seconds / 60:.0f} min"
    return f"{seconds / 3600:.1f} h"


@contextmanager
def phase(what: str, *, enabled: bool | None = None) -> Iterator[None]:
    """Say on stderr ``meshmocap: WHAT ...`` once the ``with`` block has run for
    :data:`PHASE_SECONDS` (at once where that is 0), and ``meshmocap: WHAT: done in S s``
    when it ends (short steps stay quiet). ``enabled`` False: nothing."""
    if enabled is False:
        yield
        return
    t0 = time.perf_counter()
    said = threading.Event()

    def say() -> None:
        said.set()
        sys.stderr.write(f"meshmocap: {what} ...\n")
        sys.stderr.flush()

    timer = threading.Timer(PHASE_SECONDS, say)
    timer.daemon = True
    if PHASE_SECONDS <= 0:  # every step said, at once (a test's setting: no race)
        say()
    else:
        timer.start()
    try:
        yield
    finally:
        timer.cancel()
        if said.is_set():
            sys.stderr.write(f"meshmocap: {what}: done in {time.perf_counter() - t0:.0f} s\n")
            sys.stderr.flush()
