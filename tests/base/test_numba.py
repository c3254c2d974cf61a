"""A kernel numba cannot cache (a read-only install without a writable cache folder) is
defined uncached, with one warning, instead of failing the import."""

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
