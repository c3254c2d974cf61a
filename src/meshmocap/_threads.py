"""One BLAS thread while meshmocap works, applied by the commands and the tracking driver.

On small shared machines small dense algebra is fastest single-threaded (``DESIGN.md``,
Threads); meshmocap parallelises over frames or captures instead. Users who want more
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


def thread_count() -> int:
    """The BLAS threads meshmocap uses: ``MESHMOCAP_THREADS`` (default 1)."""
    text = os.environ.get("MESHMOCAP_THREADS", "1")
    try:
        n = int(text)
    except ValueError:
        n = 0
    if n < 1:
        raise InputError(f"MESHMOCAP_THREADS must be an integer ≥ 1, found {text!r}")
    return n


@contextmanager
def blas_threads() -> Iterator[None]:
    """Cap the BLAS pools at :func:`thread_count` threads inside the ``with`` block
    (threadpoolctl), restoring the previous limits when it ends."""
    from threadpoolctl import threadpool_limits

    with threadpool_limits(thread_count(), user_api="blas"):
        yield


def limit_blas_threads() -> None:
    """For scripts (benchmarks) that want the limit for the whole process: set the
    threading variables not set yet (effective for libraries loaded afterwards) and cap the
    BLAS pools already loaded."""
    n = str(thread_count())
    for var in _VARS:
        os.environ.setdefault(var, n)
    from threadpoolctl import threadpool_limits

    threadpool_limits(int(n), user_api="blas")
