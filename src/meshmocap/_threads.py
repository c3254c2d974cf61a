"""One BLAS thread while meshmocap works, applied by the commands and the tracking driver.

On small shared machines small dense algebra is fastest single-threaded (``DESIGN.md``,
Threads; OpenMP pools, such as pykdtree's, oversubscribe a loaded machine badly);
meshmocap parallelises over frames or captures instead. Users who want more
threads set ``MESHMOCAP_THREADS``. Importing meshmocap changes nothing: the limit holds
inside :func:`blas_threads` (the commands and :func:`~meshmocap.trackers.driver.track_sequence`
enter it) and is lifted when it ends, so a notebook or a host application keeps its own
settings outside those calls.
"""

from __future__ import annotations

import os
from collections.abc import Iterator
from contextlib import contextmanager

from meshmocap.errors import InputError

_VARS = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "BLIS_NUM_THREADS")


def env_count(name: str) -> int | None:
    """The count (an integer ≥ 1) the environment variable ``name`` sets, None where it is
    unset; any other value is an :class:`~meshmocap.errors.InputError` naming it."""
    text = os.environ.get(name)
    if text is None:
        return None
    try:
        n = int(text)
    except ValueError:
        n = 0
    if n < 1:
        raise InputError(f"{name} must be an integer ≥ 1, found {text!r}")
    return n


def thread_count() -> int:
    """The BLAS threads meshmocap uses: ``MESHMOCAP_THREADS`` (default 1)."""
    n = env_count("MESHMOCAP_THREADS")
    return 1 if n is None else n


@contextmanager
def blas_threads() -> Iterator[None]:
    """One thread (:func:`thread_count`) for the BLAS and OpenMP pools inside the ``with``
    block: the pools already loaded are capped through threadpoolctl, and those loaded
    inside the block (a command imports its modules lazily: scipy's BLAS, pykdtree's
    OpenMP) read the threading variables, set for the block where the user has not. The
    limits and the variables are restored when it ends."""
    from threadpoolctl import threadpool_limits

    n = thread_count()
    saved = {var: os.environ.get(var) for var in _VARS}
    for var in _VARS:
        os.environ.setdefault(var, str(n))
    try:
        with threadpool_limits(n):
            yield
    finally:
        for var, value in saved.items():
            if value is None:
                os.environ.pop(var, None)
            else:
                os.environ[var] = value


def limit_blas_threads() -> None:
    """For scripts (benchmarks) that want the limit for the whole process: set the
    threading variables not set yet (effective for libraries loaded afterwards) and cap the
    BLAS pools already loaded."""
    n = str(thread_count())
    for var in _VARS:
        os.environ.setdefault(var, n)
    from threadpoolctl import threadpool_limits

    threadpool_limits(int(n), user_api="blas")
