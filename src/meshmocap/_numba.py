"""numba's ``njit`` for meshmocap's kernels: cached where numba can cache, compiled in each
process where it cannot, instead of failing to import.

numba caches a kernel's machine code (``cache=True``) beside its source (``__pycache__``),
or, where the installed package is read-only, in the user's cache folder
(``~/.cache/numba``), or in ``NUMBA_CACHE_DIR``. Where none of these can be written (a
read-only install run by a user without a writable home: a container, a sandbox) numba
refuses to define a cached kernel at all: importing the module raises. Here such a kernel
is defined uncached instead, with one :class:`~meshmocap.errors.KernelCacheWarning`
saying what that costs and how to avoid it.

A cached kernel is compiled by one process at a time: each compilation (or load from the
cache) holds a lock file beside the kernel's cache entry (``fcntl.flock``: Linux and macOS),
so a process that needs a kernel another is compiling (the background compiler of
:mod:`meshmocap.apps.kernels`, a forked worker) waits for it and loads what that one
cached instead of compiling it again. A process killed while compiling releases its lock;
where the lock file cannot be made, the process compiles as numba does.
"""

from __future__ import annotations

import contextlib
import os
import warnings
from collections.abc import Callable, Iterator

import numba
from numba.core import sigutils
from numba.core.compiler_lock import global_compiler_lock

from meshmocap.errors import KernelCacheWarning

__all__ = ["compiling_elsewhere", "njit"]

_warned: list[bool] = []
#: The kernels' lock files this process holds (a kernel compiled inside another's
#: compilation takes its own lock; one already held is not taken twice).
_HELD: set[str] = set()

try:
    import fcntl
except ImportError:  # pragma: no cover - Windows: no lock, every process compiles
    fcntl = None


def njit(**options) -> Callable:
    """``numba.njit(**options)``; with ``cache=True`` compiled by one process at a time
    (module docstring), and where numba has no writable place to cache, the kernel
    uncached (compiled at first use in every process) and a warning."""

    def define(fn: Callable) -> Callable:
        try:
            kernel = numba.njit(**options)(fn)
        except RuntimeError as exc:  # numba: "cannot cache function ...: no locator"
            if not options.get("cache") or "cannot cache" not in str(exc):
                raise
        else:
            if options.get("cache"):
                _compile_once(kernel)
            return kernel
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


def _compile_once(kernel) -> None:
    """Make the cached ``kernel``'s compilations (numba's ``Dispatcher.compile``, which
    loads from the cache first) hold its lock file (module docstring)."""
    compile_ = getattr(kernel, "compile", None)
    if compile_ is None or not hasattr(kernel, "overloads"):  # NUMBA_DISABLE_JIT: a function
        return

    def compile_locked(sig):
        args, _ = sigutils.normalize_signature(sig)
        if tuple(args) in kernel.overloads:  # compiled or loaded in this process already
            return compile_(sig)
        # numba's own lock first: one compilation at a time in this process, as numba
        with global_compiler_lock, _lock_file(kernel):
            return compile_(sig)

    kernel.compile = compile_locked


def _lock_path(kernel) -> str | None:
    """``kernel``'s lock file, ``<its cache entry>.lock`` (None where numba's internals
    changed)."""
    try:
        cache = kernel._cache
        return os.path.join(cache.cache_path, cache._cache_file._index_name + ".lock")
    except AttributeError:
        return None


def compiling_elsewhere(kernel) -> bool:
    """Whether another process holds the cached ``kernel``'s lock file now (compiles it or
    loads it, module docstring); False where there is no lock to look at."""
    path = _lock_path(kernel)
    if fcntl is None or path is None or path in _HELD:
        return False
    try:
        fd = os.open(path, os.O_RDWR)
    except OSError:  # no lock file: never compiled here
        return False
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        return True
    except OSError:  # a file system without locks
        return False
    finally:
        os.close(fd)  # releases the lock if it was taken
    return False


@contextlib.contextmanager
def _lock_file(kernel) -> Iterator[None]:
    """Hold ``kernel``'s lock file (:func:`_lock_path`) while the block runs; no lock
    where there is none to take (no ``fcntl``, no writable cache folder, a file system
    that refuses locks)."""
    path = _lock_path(kernel)
    if fcntl is None or path is None or path in _HELD:
        yield
        return
    try:
        kernel._cache._impl.locator.ensure_cache_path()
        fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o666)
    except OSError:
        yield
        return
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX)
        except OSError:  # a file system without locks (some network ones): compile unlocked
            yield
            return
        _HELD.add(path)
        try:
            yield
        finally:
            _HELD.discard(path)
    finally:
        os.close(fd)  # releases the lock
