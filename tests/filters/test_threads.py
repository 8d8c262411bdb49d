"""bboxtune.filters.threads: BLAS threads limited while a filter runs, and only then; importing changes nothing."""

from __future__ import annotations

import json
import subprocess
import sys
import threading

import numpy as np
import pytest
from threadpoolctl import threadpool_info, threadpool_limits

from bboxtune import filters
from bboxtune.filters import threads


def blas_counts() -> list[int]:
    return [lib["num_threads"] for lib in threadpool_info() if lib["user_api"] == "blas"]


def test_importing_every_part_leaves_the_blas_threads_alone() -> None:
    """The libraries loaded before the import keep their thread counts (later ones, e.g. torch's, bring their own)."""
    code = ("import json, numpy\nfrom threadpoolctl import threadpool_info, threadpool_limits\n"
            "threadpool_limits(3, user_api='blas')\n"
            "counts = lambda: {l['filepath']: l['num_threads'] for l in threadpool_info() if l['user_api'] == 'blas'}\n"
            "before = counts()\n"
            "import bboxtune, bboxtune.filters, bboxtune.envs, bboxtune.agents\n"
            "print(json.dumps([before, counts()]))\n")
    before, after = json.loads(subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                                              check=True).stdout)
    assert before and set(before.values()) == {3}
    assert {path: after[path] for path in before} == before


@pytest.mark.parametrize("name", [*filters.NAMES, *filters.PEER_NAMES])
def test_a_run_uses_the_set_count_and_restores_the_callers(name: str, monkeypatch: pytest.MonkeyPatch) -> None:
    seen: list[list[int]] = []
    flt = filters.make(name, filters.constant_velocity(0.05, ndim=4))
    original = type(flt)._inputs

    def spy(self: filters.Filter, *args: object) -> object:  # every back end's run checks its inputs here
        seen.append(blas_counts())
        return original(self, *args)

    monkeypatch.setenv(threads.ENV_VAR, "1")
    y = np.cumsum(np.random.default_rng(0).normal(size=(2, 40, 4)), axis=1) + 50.0
    with threadpool_limits(2, user_api="blas"):
        monkeypatch.setattr(type(flt), "_inputs", spy)
        with threads._controller().limit(limits=2, user_api="blas"):
            flt.run(y)
            assert blas_counts() and set(blas_counts()) == {2}
    assert seen and all(set(c) == {1} for c in seen)


@pytest.mark.parametrize("text", ["0", "-1", "two", "1.5", "", "1025"])
def test_a_bad_thread_count_is_refused_naming_the_variable(text: str, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv(threads.ENV_VAR, text)
    with pytest.raises(ValueError, match=f"{threads.ENV_VAR}=.*allowed: an integer in \\[1, 1024\\]"):
        filters.make("kf", filters.constant_velocity(0.05)).run(np.zeros((5, 2)))


def test_a_process_already_at_the_count_changes_nothing(monkeypatch: pytest.MonkeyPatch) -> None:
    """The fast path: every BLAS library at most at the count, so no limit is set (and none restored) per call."""
    monkeypatch.setenv(threads.ENV_VAR, "1")
    flt = filters.make("kf", filters.constant_velocity(0.05))
    with threadpool_limits(1, user_api="blas"):
        controller = threads._controller()
        monkeypatch.setattr(type(controller), "limit", lambda *a, **k: pytest.fail("limit() called on the fast path"))
        assert flt.run(np.zeros((5, 1))).shape == (5, 2)


def test_in_threads_runs_consecutive_slices_in_order(monkeypatch: pytest.MonkeyPatch) -> None:
    """Enough work: one slice per thread (at most $BBOXTUNE_KERNEL_THREADS), results in slice order; little work
    (below MIN_WORK per thread): one slice, called in the caller's thread."""
    monkeypatch.setattr(threads, "MIN_WORK", 10)
    monkeypatch.setenv(threads.KERNEL_ENV_VAR, "3")
    part = lambda s: (s.start, s.stop, threading.get_ident())  # noqa: E731
    split = threads.in_threads(part, 10, 5)
    assert [s[:2] for s in split] == [(0, 3), (3, 6), (6, 10)]
    assert threading.get_ident() not in {s[2] for s in split}
    assert [s[:2] for s in threads.in_threads(part, 10, 2)] == [(0, 5), (5, 10)]  # 20 units: 2 threads of 10
    assert threads.in_threads(part, 10, 1) == [(0, 10, threading.get_ident())]  # 10 units: one thread
    monkeypatch.setenv(threads.KERNEL_ENV_VAR, "1")
    assert threads.in_threads(part, 10, 100) == [(0, 10, threading.get_ident())]


@pytest.mark.parametrize("text", ["0", "-1", "two", "", "1025"])
def test_a_bad_kernel_thread_count_is_refused_naming_the_variable(text: str, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv(threads.KERNEL_ENV_VAR, text)
    with pytest.raises(ValueError, match=f"{threads.KERNEL_ENV_VAR}=.*allowed: an integer in \\[1, 1024\\]"):
        threads.kernel_threads()


def test_in_threads_keeps_its_threads_and_runs_a_nested_call_in_place(monkeypatch: pytest.MonkeyPatch) -> None:
    """The pool's threads serve call after call; a call from one of them runs there, in one slice (a nested split
    would wait on the pool it runs in)."""
    monkeypatch.setattr(threads, "MIN_WORK", 1)
    monkeypatch.setenv(threads.KERNEL_ENV_VAR, "2")
    ident = lambda s: (threading.get_ident(), threading.current_thread().name)  # noqa: E731
    calls = [threads.in_threads(ident, 4, 1) for _ in range(10)]
    workers = {thread for call in calls for thread in call}
    assert len(workers) <= 2 and all(name.startswith("bboxtune-kernel") for _, name in workers)
    first = [ident for ident, _ in workers]

    def nested(s: slice) -> list[tuple[int, int, int]]:
        return threads.in_threads(lambda inner: (inner.start, inner.stop, threading.get_ident()), 6, 1)
    for inner, worker in zip(threads.in_threads(nested, 2, 1), first, strict=True):
        assert [part[:2] for part in inner] == [(0, 6)] and inner[0][2] in first
        assert worker in first


def test_a_forked_process_gets_a_pool_of_its_own(monkeypatch: pytest.MonkeyPatch) -> None:
    """The pool is kept per process id: a forked child, which has none of its parent's threads, starts its own."""
    monkeypatch.setattr(threads, "MIN_WORK", 1)
    monkeypatch.setenv(threads.KERNEL_ENV_VAR, "2")
    parent = threads._pool(2)
    monkeypatch.setattr(threads.os, "getpid", lambda: -1)
    child = threads._pool(2)
    assert child is not parent and threads.in_threads(lambda s: s.stop - s.start, 4, 1) == [2, 2]


def test_a_slice_that_raises_raises_in_the_caller(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(threads, "MIN_WORK", 1)
    monkeypatch.setenv(threads.KERNEL_ENV_VAR, "2")

    def second_fails(s: slice) -> int:
        if s.start:
            raise FloatingPointError("slice failed")
        return 0
    with pytest.raises(FloatingPointError, match="slice failed"):
        threads.in_threads(second_fails, 4, 1)
