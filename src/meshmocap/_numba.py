"""numba's ``njit`` for meshmocap's kernels: cached where numba can cache, compiled in each
process where it cannot, instead of failing to import.

numba caches a kernel's machine code (``cache=True``) beside its source (``__pycache__``),
or, where the installed package is read-only, in the user's cache folder
(``~/.cache/numba``), or in ``NUMBA_CACHE_DIR``. Where none of these can be written (a
read-only install run by a user without a writable home: a container, a sandbox) numba
refuses to define a cached kernel at all: importing the module raises. Here such a kernel
is defined uncached instead, with one :class:`~meshmocap.errors.KernelCacheWarning`
saying what that costs and how to avoid it.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable

import numba

from meshmocap.errors import KernelCacheWarning

__all__ = ["njit"]

_warned: list[bool] = []


def njit(**options) -> Callable:
    """``numba.njit(**options)``; with ``cache=True`` where numba has no writable place to
    cache, the kernel uncached (compiled at first use in every process) and a warning."""

    def define(fn: Callable) -> Callable:
        try:
            return numba.njit(**options)(fn)
        except RuntimeError as exc:  # numba: "cannot cache function ...: no locator"
            if not options.get("cache") or "cannot cache" not in str(exc):
                raise
        if not _warned:
            _warned.append(True)
            warnings.warn(
                "numba cannot cache meshmocap's compiled kernels (the package is read-only "
                "and the user's cache folder cannot be written): they compile again in "
                "every process (about a minute); set NUMBA_CACHE_DIR to a writable folder",
                KernelCacheWarning,
                stacklevel=3,
            )
        return numba.njit(**{**options, "cache": False})(fn)

    return define
