"""The BLAS thread limit: importing meshmocap leaves the host's settings alone; the commands
and the tracking driver apply it, and lift it when they end."""

import os
import subprocess
import sys
from pathlib import Path

import numpy  # noqa: F401  (loads the BLAS library whose pool the limit caps)
import pytest
from threadpoolctl import threadpool_info

from meshmocap._threads import blas_threads, thread_count
from meshmocap.errors import InputError

SRC = str(Path(__file__).resolve().parents[2] / "src")


def _blas_threads() -> list[int]:
    return [p["num_threads"] for p in threadpool_info() if p["user_api"] == "blas"]


def test_importing_meshmocap_leaves_the_thread_limits_alone():
    """In a fresh process with two BLAS threads, importing the package, its driver and its
    command module changes neither the pools (scipy's loads one more, at two threads too)
    nor the environment."""
    code = (
        "import os, numpy\n"
        "from threadpoolctl import threadpool_info\n"
        "def pools():\n"
        "    return [p['num_threads'] for p in threadpool_info() if p['user_api'] == 'blas']\n"
        "before, env = pools(), dict(os.environ)\n"
        "import meshmocap, meshmocap.trackers.driver, meshmocap.cli\n"
        "assert set(pools()) == set(before) == {2}, (before, pools())\n"
        "assert dict(os.environ) == env\n"
        "print(before)\n"
    )
    env = {k: v for k, v in os.environ.items() if not k.endswith("_NUM_THREADS")}
    env.update(OPENBLAS_NUM_THREADS="2", PYTHONPATH=SRC)
    env.pop("MESHMOCAP_THREADS", None)
    run = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True)
    assert run.returncode == 0, run.stderr
    assert run.stdout.strip() == "[2]"  # the host's setting, untouched


def test_the_limit_holds_inside_blas_threads_and_is_lifted_after(monkeypatch):
    from threadpoolctl import threadpool_limits

    with threadpool_limits(2, user_api="blas"):
        outside = _blas_threads()
        monkeypatch.delenv("MESHMOCAP_THREADS", raising=False)
        with blas_threads():
            assert set(_blas_threads()) == {1}
        assert _blas_threads() == outside


def test_meshmocap_threads_is_read_and_checked(monkeypatch):
    monkeypatch.setenv("MESHMOCAP_THREADS", "3")
    assert thread_count() == 3
    monkeypatch.setenv("MESHMOCAP_THREADS", "many")
    with pytest.raises(InputError, match="MESHMOCAP_THREADS must be an integer ≥ 1, found 'many'"):
        thread_count()
