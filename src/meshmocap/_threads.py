"""Default to one BLAS thread.

On small shared machines small dense algebra is fastest single-threaded: a 120×120 product
takes 38 µs on one thread and up to 15 ms on two when the other core is busy. meshmocap
parallelises over frames instead. Users who want more threads set ``MESHMOCAP_THREADS``.
"""

from __future__ import annotations

import os

_VARS = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "BLIS_NUM_THREADS")


def limit_blas_threads() -> None:
    """Cap BLAS/OpenMP threads at ``MESHMOCAP_THREADS`` (default 1).

    Environment variables the user already set are respected. When numpy is already
    imported its BLAS pool is capped through threadpoolctl if that package is installed.
    """
    n = os.environ.get("MESHMOCAP_THREADS", "1")
    for var in _VARS:
        os.environ.setdefault(var, n)
    try:
        from threadpoolctl import threadpool_limits
    except ImportError:  # pragma: no cover - optional
        return
    threadpool_limits(int(n), user_api="blas")
