"""Independent pieces of one job run side by side in forked worker processes, one per core.

The machines meshmocap runs on are small (``DESIGN.md``, Threads): one BLAS thread, and
the cores used by running independent pieces of work at once: the frames of the body's
shape fit, the first pose's candidates, the demo's trackers. :class:`Workers` maps a
function over such pieces in a pool of processes forked from this one, so the pieces'
inputs (silhouettes, templates, a capture) are inherited, never pickled, and only their
arguments and results travel. The results are the serial run's to the bit: each piece
is computed by the same code on the same inputs, and they come back in order.

How many: ``MESHMOCAP_JOBS`` (an integer ≥ 1), else the cores this process may run on
(``os.sched_getaffinity``: ``taskset`` limits it), never more than the pieces. One job, a
platform without ``fork`` (only Linux forks here: macOS's system libraries are not
fork-safe), a worker's own pieces or this process's while a pool of it is open (no pool
inside a pool): everything runs in this process, one piece after the other, as before.

A worker runs one BLAS and OpenMP thread (``MESHMOCAP_THREADS`` applies to this
process only), prints what it prints (its progress lines interleave with the parent's),
and shows its warnings rather than raising them in the parent.
"""

from __future__ import annotations

import itertools
import multiprocessing
import os
import sys
from collections.abc import Callable, Iterator, Sequence

from meshmocap._threads import env_count

__all__ = ["JOBS_ENV", "Workers", "job_count", "parallel_map"]

#: Environment variable: how many worker processes (1: none, everything in this process).
JOBS_ENV = "MESHMOCAP_JOBS"

#: The functions of the pools open in this process, by key (inherited by their workers).
_FUNCTIONS: dict[int, Callable] = {}
_KEYS = itertools.count()
#: Whether this process is a pool's worker (its own pieces run serially).
_IN_WORKER = [False]
#: Pools open in this process: while one is, this process's own pieces (the leftover one
#: it computes meanwhile) run serially too, the cores being busy.
_OPEN = [0]


def _cores() -> int:
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1


def job_count() -> int:
    """The worker processes a job may use: ``MESHMOCAP_JOBS``, else the cores this process
    may run on; 1 inside a worker and where processes are not forked (module docstring)."""
    n = env_count(JOBS_ENV)
    if n is None:
        n = _cores()
    if _IN_WORKER[0] or _OPEN[0] or not sys.platform.startswith("linux"):
        return 1
    if multiprocessing.current_process().daemon:  # a caller's pool worker: no children
        return 1
    return n


def _start_worker() -> None:
    """A worker's setup: its own pieces serial, and one thread in the BLAS and OpenMP pools
    (GNU OpenMP's pool does not survive a fork: a parallel region of more than one thread
    in a forked child hangs where the parent had used the pool)."""
    from threadpoolctl import threadpool_limits

    _IN_WORKER[0] = True
    threadpool_limits(1)


def _call(task: tuple) -> object:
    key, args = task
    return _FUNCTIONS[key](*args)


class Workers:
    """A pool of forked processes running ``func`` on pieces of work, as a context manager:
    ``with Workers(func, n) as w: results = w.map(args)``. The pool is forked when the
    ``with`` block starts (the state ``func`` reads then is what the workers see) and ends
    with it; several :meth:`map` calls share it.

    Parameters
    ----------
    func : callable, called as ``func(*args)`` for each piece
    pieces : int, the most pieces one :meth:`map` call will give (no more workers are
        started; 1 or fewer: no pool)
    """

    def __init__(self, func: Callable, pieces: int):
        self.func = func
        self.jobs = max(1, min(job_count(), int(pieces)))
        self._key: int | None = None
        self._pool = None

    def __enter__(self) -> Workers:
        if self.jobs > 1:
            self._key = next(_KEYS)
            _FUNCTIONS[self._key] = self.func
            sys.stdout.flush()  # nothing buffered before the fork is written twice
            sys.stderr.flush()
            ctx = multiprocessing.get_context("fork")
            self._pool = ctx.Pool(self.jobs, initializer=_start_worker)
            _OPEN[0] += 1
        return self

    def __exit__(self, *exc) -> None:
        if self._pool is not None:
            self._pool.terminate()
            self._pool.join()
            self._pool = None
            _OPEN[0] -= 1
        if self._key is not None:
            _FUNCTIONS.pop(self._key, None)
            self._key = None

    def map(
        self, args: Sequence[tuple], *, here: int | None = None, meanwhile: Callable | None = None
    ) -> list:
        """``[func(*a) for a in args]``, the pieces spread over the workers; in order. A
        piece's exception is raised here.

        ``here``: the last pieces computed by this process while the workers compute the
        others (default: the pieces left over when they are shared evenly among the
        workers, so that no core waits for one worker's extra piece). ``meanwhile``: a
        callable (no arguments) this process calls after its own pieces, before it waits
        for the workers' (after every piece without workers): other work of its own."""
        args = [tuple(a) for a in args]
        if self._pool is None:
            out = [self.func(*a) for a in args]
            if meanwhile is not None:
                meanwhile()
            return out
        here = len(args) % self.jobs if here is None else max(0, min(int(here), len(args)))
        cut = len(args) - here
        tasks = [(self._key, a) for a in args[:cut]]
        pending = self._pool.map_async(_call, tasks, chunksize=1)
        try:
            mine = [self.func(*a) for a in args[cut:]]
            if meanwhile is not None:
                meanwhile()
        finally:
            done = pending.get()  # the workers' pieces (their error raised here)
        return done + mine

    def imap(self, args: Sequence[tuple]) -> Iterator:
        """:meth:`map`'s results, each yielded as soon as it and those before it are done
        (a progress bar can follow them)."""
        if self._pool is None:
            return (self.func(*a) for a in args)
        return self._pool.imap(_call, [(self._key, tuple(a)) for a in args], chunksize=1)


def parallel_map(func: Callable, items: Sequence) -> list:
    """``[func(x) for x in items]``, the items spread over worker processes and this one
    (:class:`Workers`); in order, the serial results to the bit."""
    items = list(items)
    with Workers(func, len(items)) as w:
        return w.map([(x,) for x in items])
