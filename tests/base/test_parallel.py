"""Pieces of one job in forked workers: the serial results, in order, whatever the count."""

import os

import numpy as np
import pytest

from meshmocap import _parallel
from meshmocap._parallel import JOBS_ENV, Workers, job_count, parallel_map
from meshmocap.errors import InputError


def _piece(seed):
    """A piece of float work whose result depends on every bit of its input."""
    rng = np.random.default_rng(seed)
    A = rng.standard_normal((40, 40))
    return np.linalg.solve(A @ A.T + np.eye(40), rng.standard_normal(40)), os.getpid()


def test_the_pieces_come_back_in_order_and_equal_to_the_bit(monkeypatch):
    """Two workers give the serial results bit for bit, in order, computed in other
    processes; inputs are inherited (a closure over a local array, never pickled)."""
    monkeypatch.setenv(JOBS_ENV, "2")
    offset = np.random.default_rng(1).standard_normal(40)  # read by the workers, inherited
    serial = [_piece(s)[0] + offset for s in range(5)]
    out = parallel_map(lambda s: (_piece(s)[0] + offset, os.getpid()), range(5))
    assert all(np.array_equal(a, b) for a, (b, _) in zip(serial, out, strict=True))
    # four pieces in the two workers, the fifth (left over) here meanwhile
    assert os.getpid() not in {pid for _, pid in out[:4]} and out[4][1] == os.getpid()
    with Workers(lambda a, b: (a * b, os.getpid()), 3) as w:  # several maps share one pool
        assert w.jobs == 2
        assert [x for x, _ in w.map([(1, 2), (3, 4), (5, 6)])] == [2, 12, 30]
        assert {pid for _, pid in w.map([(1, 1), (2, 2)], here=2)} == {os.getpid()}
        assert os.getpid() not in {pid for _, pid in w.map([(2, 2)], here=0)}
        assert job_count() == 1  # while the pool is open, this process's pieces run here
        assert [x for x, _ in w.imap([(1, 3), (2, 3)])] == [3, 6]


@pytest.mark.parametrize("jobs", ["1", "2"])
def test_other_work_runs_here_meanwhile(monkeypatch, jobs):
    """``meanwhile`` runs once in this process, after its own pieces (with workers: while
    they compute theirs), with or without a pool; the pieces' results are unchanged."""
    monkeypatch.setenv(JOBS_ENV, jobs)
    seen = []
    with Workers(lambda a: (a * 2, os.getpid()), 3) as w:
        out = w.map([(1,), (2,), (3,)], meanwhile=lambda: seen.append(os.getpid()))
    assert [x for x, _ in out] == [2, 4, 6] and seen == [os.getpid()]
    if jobs == "2":  # the left-over piece ran here before the other work
        assert out[2][1] == os.getpid() and os.getpid() not in {p for _, p in out[:2]}


def test_one_job_runs_here_and_a_worker_runs_its_own_serially(monkeypatch):
    monkeypatch.setenv(JOBS_ENV, "1")
    assert job_count() == 1
    assert {pid for _, pid in parallel_map(_piece, range(3))} == {os.getpid()}
    monkeypatch.setenv(JOBS_ENV, "2")
    inner = parallel_map(lambda _: (job_count(), Workers(abs, 4).jobs), range(2))
    assert inner == [(1, 1), (1, 1)]  # no pool inside a pool
    assert Workers(abs, 1).jobs == 1  # never more workers than pieces
    monkeypatch.setattr(_parallel.sys, "platform", "darwin")
    assert job_count() == 1  # forked only on Linux


def test_a_piece_s_error_is_raised_and_a_bad_count_named(monkeypatch):
    monkeypatch.setenv(JOBS_ENV, "2")

    def fail(x):
        if x == 2:
            raise InputError(f"piece {x} failed")
        return x

    with pytest.raises(InputError, match="piece 2 failed"):
        parallel_map(fail, range(4))
    assert job_count() == 2  # the pool closed
    for bad in ("0", "two"):
        monkeypatch.setenv(JOBS_ENV, bad)
        with pytest.raises(InputError, match=f"{JOBS_ENV} must be an integer ≥ 1, found '{bad}'"):
            job_count()
    monkeypatch.delenv(JOBS_ENV)
    assert job_count() == len(os.sched_getaffinity(0))


def _jobs_and_pieces():
    return job_count(), parallel_map(abs, [-1, -2, -3])


def test_a_caller_s_pool_worker_runs_its_pieces_itself(monkeypatch):
    """Inside a daemonic worker of a caller's multiprocessing pool (which may not have
    children of its own), pieces run serially instead of failing."""
    import multiprocessing

    monkeypatch.setenv(JOBS_ENV, "2")
    with multiprocessing.get_context("fork").Pool(1) as pool:
        assert pool.apply(_jobs_and_pieces) == (1, [1, 2, 3])
