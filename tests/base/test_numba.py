"""A kernel numba cannot cache (a read-only install without a writable cache folder) is
defined uncached, with one warning, instead of failing the import."""

import functools
import os
import subprocess
import sys

import numba
import pytest

import meshmocap._numba as kernels
from meshmocap.errors import KernelCacheWarning


def test_a_kernel_numba_cannot_cache_is_compiled_uncached_with_one_warning(monkeypatch):
    real = numba.njit

    def no_locator(**options):
        if options.get("cache"):

            def fail(fn):
                raise RuntimeError(f"cannot cache function {fn.__name__!r}: no locator available")

            return fail
        return real(**options)

    monkeypatch.setattr(kernels, "_warned", [])
    with (
        monkeypatch.context() as patch,
        pytest.warns(KernelCacheWarning, match="set NUMBA_CACHE_DIR") as caught,
    ):
        patch.setattr(kernels.numba, "njit", no_locator)

        @kernels.njit(cache=True, nogil=True)
        def twice(x):
            return 2 * x

        @kernels.njit(cache=True)
        def thrice(x):
            return 3 * x

    assert len(caught) == 1  # one warning for every kernel
    assert twice(21) == 42 and thrice(2) == 6
    assert twice._cache.__class__.__name__ == "NullCache"


def test_a_cacheable_kernel_is_cached_and_other_errors_pass_through(monkeypatch):
    @kernels.njit(cache=True)
    def plus_one(x):
        return x + 1

    assert plus_one(1) == 2 and plus_one._cache.__class__.__name__ != "NullCache"

    def broken(**options):
        def fail(fn):
            raise RuntimeError("something else")

        return fail

    monkeypatch.setattr(kernels.numba, "njit", broken)
    with pytest.raises(RuntimeError, match="something else"):
        kernels.njit(cache=True)(lambda x: x)


_KERNEL = """
from meshmocap._numba import njit


@njit(cache=True)
def double(x):
    return 2 * x
"""

_HOLDER = """
import sys, time
from meshmocap._numba import _lock_file
from kernel import double

with _lock_file(double):
    print("locked", flush=True)
    sys.stdin.readline()  # the other process is about to call the kernel
    time.sleep(0.5)  # and waits for this lock
    double(2)  # compiled here and cached, the lock held
print(sum(double.stats.cache_misses.values()), sum(double.stats.cache_hits.values()))
"""

_CALLER = """
from kernel import double

print("calling", flush=True)
double(3)
print(sum(double.stats.cache_misses.values()), sum(double.stats.cache_hits.values()))
"""


@pytest.mark.slow
def test_a_kernel_another_process_is_compiling_is_loaded_from_its_cache_not_compiled(tmp_path):
    """One process holds a kernel's lock (as while compiling it); another that calls the
    kernel meanwhile waits for the lock and then loads what the first cached: the kernel
    is compiled once (one cache miss in all), not by both."""
    (tmp_path / "kernel.py").write_text(_KERNEL)
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "cache")}
    env["PYTHONPATH"] = os.pathsep.join([str(tmp_path), env.get("PYTHONPATH", "")])
    run = functools.partial(
        subprocess.Popen,
        env=env,
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    with run([sys.executable, "-c", _HOLDER]) as holder:
        assert holder.stdout.readline().strip() == "locked", holder.communicate()[1]
        with run([sys.executable, "-c", _CALLER]) as caller:
            assert caller.stdout.readline().strip() == "calling", caller.communicate()[1]
            held, _ = holder.communicate("go\n", timeout=120)
            called, err = caller.communicate(timeout=120)
    assert held.split() == ["1", "0"]  # compiled by the holder
    assert called.split()[-2:] == ["0", "1"], err  # loaded by the caller: no second compile


_CHECK = """
from meshmocap._numba import compiling_elsewhere
from kernel import double

print(compiling_elsewhere(double))
"""


@pytest.mark.skipif(kernels.fcntl is None, reason="no fcntl: no lock taken")
def test_a_kernel_another_process_holds_the_lock_of_is_compiling_elsewhere(tmp_path):
    """While one process holds a kernel's lock, another sees the kernel being compiled
    elsewhere (the background compiler then compiles the next one meanwhile); once the
    lock is released, it does not."""
    (tmp_path / "kernel.py").write_text(_KERNEL)
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "cache")}
    env["PYTHONPATH"] = os.pathsep.join([str(tmp_path), env.get("PYTHONPATH", "")])

    def check() -> str:
        p = subprocess.run(
            [sys.executable, "-c", _CHECK], env=env, capture_output=True, text=True, timeout=120
        )
        assert p.returncode == 0, p.stderr[-2000:]
        return p.stdout.strip()

    assert check() == "False"  # no lock file yet: never compiled
    with subprocess.Popen(
        [sys.executable, "-c", _HOLDER],
        env=env,
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    ) as holder:
        assert holder.stdout.readline().strip() == "locked", holder.communicate()[1]
        held = check()
        holder.communicate("go\n", timeout=120)
    assert (held, check()) == ("True", "False")


@pytest.mark.skipif(kernels.fcntl is None, reason="no fcntl: no lock taken")
def test_a_file_system_that_refuses_locks_compiles_unlocked(monkeypatch):
    """Where ``flock`` fails (some network file systems) the kernel compiles as numba does."""

    @kernels.njit(cache=True)
    def triple(x):
        return 3 * x

    def refuse(fd, op):
        raise OSError(37, "No locks available")

    monkeypatch.setattr(kernels.fcntl, "flock", refuse)
    assert triple(2) == 6
